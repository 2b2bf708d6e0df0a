/// \file shards.cpp
/// `validate --shard i/N` and `validate --merge` (octocd/shards.hpp).

#include "octocd/shards.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <set>

#include <fmt/format.h>

#include "octocd/atomic_file.hpp"
#include "octocd/error.hpp"
#include "octocd/validation_rows.hpp"

namespace octocd {

namespace {

using json = nlohmann::json;

/// A JSON number (null: NaN, as results_json writes non-finite figures).
double number(const json& v) { return v.is_number() ? v.get<double>() : std::numeric_limits<double>::quiet_NaN(); }

/// Whether `row`'s `measured` merges by the maximum (RowMerge::Max, octocd/validation_rows.hpp);
/// every other row, and a row this build does not know, by the sum.
bool measures_largest(const std::string& row) {
  const RowInfo* info = find_row_info(row);
  return info != nullptr && info->merge == RowMerge::Max;
}

}  // namespace

ShardSpec parse_shard(const std::string& text) {
  const std::size_t slash = text.find('/');
  auto bad = [&]() {
    return InputError(fmt::format("--shard: '{}'; allowed: i/N with integers 1 <= N <= 100000 and 0 <= i < N "
                                  "(e.g. 0/4 .. 3/4)",
                                  text));
  };
  if (slash == std::string::npos) throw bad();
  const std::string a = text.substr(0, slash), b = text.substr(slash + 1);
  auto digits = [](const std::string& s) {
    return !s.empty() && s.size() <= 6 && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
  };
  if (!digits(a) || !digits(b)) throw bad();
  ShardSpec s{std::stoi(a), std::stoi(b)};
  if (s.count < 1 || s.count > 100000 || s.index < 0 || s.index >= s.count) throw bad();
  return s;
}

std::pair<std::int64_t, std::int64_t> shard_frames(ShardSpec s, std::int64_t frames) {
  const auto edge = [&](std::int64_t k) {
    // floor(k F / N): k F <= 10^5 x 10^8 (trace_limits::kMaxFrames) fits in 64 bits.
    return k * frames / s.count;
  };
  return {edge(s.index) + 1, edge(s.index + 1)};
}

nlohmann::ordered_json shard_json(ShardSpec s, const ShardIdentity& id) {
  const auto [first, last] = shard_frames(s, id.frames);
  nlohmann::ordered_json tol = nlohmann::ordered_json::object();
  for (const ToleranceEntry& e : tolerance_table()) tol[e.name] = id.tol.*(e.member);
  return {{"index", s.index},   {"count", s.count},     {"first_frame", first}, {"last_frame", last},
          {"trace", id.trace},  {"trace_bytes", id.trace_bytes}, {"engine", id.engine}, {"bodies", id.bodies},
          {"frames", id.frames}, {"every", id.every},   {"against", id.against}, {"tolerances", tol}};
}

MergedValidation merge_validations(const std::vector<std::string>& files) {
  std::vector<json> docs;
  for (const std::string& f : files) {
    // A regular file of at most 64 MiB, checked before it is read (a FIFO never blocks).
    const std::string text = read_input_file(
        f, "--merge", "JSON files written by `validate --trace-in ... --shard i/N --json FILE`");
    json d = json::parse(text, nullptr, false);
    if (d.is_discarded())
      throw InputError(fmt::format("--merge: {}: not JSON; allowed: the --json file of `validate --shard`", f));
    docs.push_back(std::move(d));
  }
  return merge_validation_docs(docs, files);
}

MergedValidation merge_validation_docs(const std::vector<json>& docs, const std::vector<std::string>& names) {
  if (docs.empty()) throw InputError("--merge: no shard files; allowed: the --json files of every shard 0/N .. N-1/N");
  struct Shard {
    std::size_t doc;
    int index = 0, count = 0;
    std::int64_t first = 0, last = 0;
    json identity;
  };
  std::vector<Shard> shards;
  for (std::size_t k = 0; k < docs.size(); ++k) {
    const json& d = docs[k];
    const std::string& name = names[k];
    auto bad = [&](const std::string& what) {
      return InputError(fmt::format("--merge: {}: {}; allowed: the --json file of `validate --trace-in TRACE "
                                    "--shard i/N`",
                                    name, what));
    };
    if (!d.is_object() || !d.contains("shard") || !d["shard"].is_object())
      throw bad("no \"shard\" object (not a shard's verdict)");
    const json& s = d["shard"];
    for (const char* key : {"index", "count", "first_frame", "last_frame", "frames", "bodies", "every"})
      if (!s.contains(key) || !s[key].is_number_integer()) throw bad(fmt::format("shard.{} missing or not an integer", key));
    if (!d.contains("rows") || !d["rows"].is_array()) throw bad("no \"rows\" array");
    Shard sh;
    sh.doc = k;
    sh.index = s["index"].get<int>();
    sh.count = s["count"].get<int>();
    sh.first = s["first_frame"].get<std::int64_t>();
    sh.last = s["last_frame"].get<std::int64_t>();
    if (sh.count < 1 || sh.index < 0 || sh.index >= sh.count)
      throw bad(fmt::format("shard {}/{}: index out of range", sh.index, sh.count));
    sh.identity = s;
    for (const char* key : {"index", "first_frame", "last_frame"}) sh.identity.erase(key);
    const auto want = shard_frames({sh.index, sh.count}, s["frames"].get<std::int64_t>());
    if (want.first != sh.first || want.second != sh.last)
      throw bad(fmt::format("shard {}/{} holds frames {}..{}, its share of {} frames is {}..{}", sh.index, sh.count,
                            sh.first, sh.last, s["frames"].get<std::int64_t>(), want.first, want.second));
    shards.push_back(std::move(sh));
  }
  // One run: the same trace, engine, frames, checks and tolerances.
  const Shard& ref = shards.front();
  for (const Shard& sh : shards) {
    if (sh.identity == ref.identity) continue;
    std::string what;
    for (auto it = ref.identity.begin(); it != ref.identity.end(); ++it)
      if (!sh.identity.contains(it.key()) || sh.identity[it.key()] != it.value()) {
        what = fmt::format("{} {} differs from {}'s {}", it.key(),
                           sh.identity.contains(it.key()) ? sh.identity[it.key()].dump() : "(missing)", names[ref.doc],
                           it.value().dump());
        break;
      }
    if (what.empty()) what = fmt::format("its run differs from {}'s", names[ref.doc]);
    throw InputError(fmt::format("--merge: {}: not a shard of the same run: {}; allowed: the shards of one "
                                 "`validate --trace-in TRACE --shard i/N` run (same trace, engine, frames, --every, "
                                 "--against and tolerances)",
                                 names[sh.doc], what));
  }
  std::sort(shards.begin(), shards.end(), [](const Shard& a, const Shard& b) { return a.index < b.index; });
  for (std::size_t k = 1; k < shards.size(); ++k)
    if (shards[k].index == shards[k - 1].index)
      throw InputError(fmt::format("--merge: {}: shard {}/{} overlaps {} (the same frames {}..{}); allowed: each "
                                   "shard once",
                                   names[shards[k].doc], shards[k].index, shards[k].count, names[shards[k - 1].doc],
                                   shards[k].first, shards[k].last));
  for (int i = 0; i < ref.count; ++i)
    if (std::size_t(i) >= shards.size() || shards[std::size_t(i)].index != i) {
      const auto fr = shard_frames({i, ref.count}, ref.identity["frames"].get<std::int64_t>());
      std::string given;
      for (const std::string& n : names) given += (given.empty() ? "" : ", ") + n;
      throw InputError(fmt::format("--merge: shard {}/{} (frames {}..{}) is missing among {}; allowed: every shard "
                                   "0/{} .. {}/{}",
                                   i, ref.count, fr.first, fr.second, given, ref.count, ref.count - 1, ref.count));
    }

  MergedValidation m;
  const json& id = ref.identity;
  m.identity.trace = id.value("trace", "");
  m.identity.trace_bytes = id.value("trace_bytes", std::uint64_t(0));
  m.identity.engine = id.value("engine", "");
  m.identity.bodies = id["bodies"].get<std::int64_t>();
  m.identity.frames = id["frames"].get<std::int64_t>();
  m.identity.every = id["every"].get<int>();
  m.identity.against = id.value("against", "");
  if (id.contains("tolerances") && id["tolerances"].is_object())
    for (const ToleranceEntry& e : tolerance_table())
      if (id["tolerances"].contains(e.name)) m.identity.tol.*(e.member) = number(id["tolerances"][e.name]);
  m.run.trace = m.identity.trace;
  for (const Shard& sh : shards) m.files.push_back(names[sh.doc]);

  // Rows: the same rows in the same order in every shard.
  const json& rows0 = docs[ref.doc]["rows"];
  for (const Shard& sh : shards) {
    const json& rows = docs[sh.doc]["rows"];
    bool same = rows.size() == rows0.size();
    for (std::size_t r = 0; same && r < rows.size(); ++r)
      same = rows[r].value("name", "") == rows0[r].value("name", "") &&
             rows[r].value("tier", "") == rows0[r].value("tier", "");
    if (!same)
      throw InputError(fmt::format("--merge: {}: its rows differ from {}'s (another octocd build?); allowed: shards "
                                   "of one run",
                                   names[sh.doc], names[ref.doc]));
  }
  for (std::size_t r = 0; r < rows0.size(); ++r) {
    ValidationResult out;
    const json& first = rows0[r];
    out.tier = first.value("tier", "") == "physics" ? Tier::Physics : Tier::Model;
    out.name = first.value("name", "");
    out.figure = first.value("figure", "");
    out.bound = number(first["bound"]);
    out.tolerances = first.value("tolerances", "");
    const bool counts = !measures_largest(out.name);
    out.measured = 0;
    out.applicable = false;
    out.pass = true;
    std::string fail_detail, first_detail;
    const std::vector<std::string> documented = documented_causes(out.name);
    std::vector<ValidationCause> causes;
    std::vector<std::set<std::string>> items;
    for (const Shard& sh : shards) {
      const json& row = docs[sh.doc]["rows"][r];
      const std::string verdict = row.value("verdict", "");
      const double measured = number(row["measured"]);
      out.measured = counts ? out.measured + measured : std::max(out.measured, measured);
      if (std::isnan(measured)) out.measured = measured;
      out.judged += row.value("judged", std::uint64_t(0));
      out.seconds += number(row["seconds"]);
      if (verdict != "n/a") out.applicable = true;
      const bool failed = verdict == "fail" || verdict == "expected";
      if (failed && out.pass) fail_detail = row.value("detail", "");
      if (first_detail.empty()) first_detail = row.value("detail", "");
      if (failed) out.pass = false;
      if (documented.empty() || !row.contains("causes")) continue;  // one cause named like the row: rebuilt
      for (const json& c : row["causes"]) {
        const std::string cname = c.value("name", "");
        auto it = std::find_if(causes.begin(), causes.end(), [&](const ValidationCause& x) { return x.name == cname; });
        if (it == causes.end()) {
          ValidationCause nc;
          nc.name = cname;
          nc.unit = c.value("unit", "");
          causes.push_back(nc);
          items.emplace_back();
          it = causes.end() - 1;
        }
        std::set<std::string>& its = items[std::size_t(it - causes.begin())];
        it->count += c.value("count", std::uint64_t(0));
        it->worst = std::max(it->worst, number(c["worst"]));
        for (const json& x : c["examples"])
          it->examples.push_back({x.value("frame", std::int64_t(-1)), x.value("item", ""), number(x["figure"]),
                                  x.value("text", "")});
        for (const json& s : c["items"]) its.insert(s.get<std::string>());
        if (!c.value("items_complete", true)) it->items_complete = false;
      }
    }
    for (std::size_t k = 0; k < causes.size(); ++k) {
      // The first examples of the whole run: a shard's examples are in frame order, but a
      // soft-contact episode begun in a shard is judged (an example) at the frame it
      // closes, which may lie in the next shard's frames: by frame, then shard order.
      std::vector<ValidationExample>& ex = causes[k].examples;
      if (std::all_of(ex.begin(), ex.end(), [](const ValidationExample& e) { return e.frame >= 0; }))
        std::stable_sort(ex.begin(), ex.end(),
                         [](const ValidationExample& a, const ValidationExample& b) { return a.frame < b.frame; });
      if (ex.size() > ValidationCause::kMaxExamples) ex.resize(ValidationCause::kMaxExamples);
      for (const std::string& s : items[k]) {
        if (causes[k].items.size() == ValidationCause::kMaxItems) {
          causes[k].items_complete = false;
          break;
        }
        causes[k].items.push_back(s);
      }
    }
    // The row's documented order.
    auto rank = [&](const ValidationCause& c) {
      const auto it = std::find(documented.begin(), documented.end(), c.name);
      return std::size_t(it - documented.begin());
    };
    std::stable_sort(causes.begin(), causes.end(),
                     [&](const ValidationCause& a, const ValidationCause& b) { return rank(a) < rank(b); });
    out.causes = std::move(causes);
    out.detail = !out.pass ? fail_detail : first_detail;
    m.results.push_back(std::move(out));
  }
  return m;
}

}  // namespace octocd
