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
#include "octocd/json_fields.hpp"
#include "octocd/json_strict.hpp"
#include "octocd/trace_reader.hpp"
#include "octocd/validation_rows.hpp"

namespace octocd {

namespace {

using json = nlohmann::json;

/// What a shard's file may hold (docs/validation-output.md, "Shards"); beyond it is bad input.
constexpr std::uint64_t kMaxCount = std::uint64_t(1) << 53;  ///< counts and judged items: exact in a double
constexpr std::size_t kMaxName = 4096;                        ///< bytes of a name (trace, engine, item, unit)
constexpr std::size_t kMaxText = std::size_t(1) << 20;        ///< bytes of a detail or an example's text
constexpr double kMaxFigure = 1e30;                           ///< |a figure|: sums over 10^5 shards stay finite
constexpr double kMaxSeconds = 1e9;                           ///< a row's seconds

/// Whether `row`'s `measured` merges by the maximum (RowMerge::Max, octocd/validation_rows.hpp);
/// every other row, and a row this build does not know, by the sum.
bool measures_largest(const std::string& row) {
  const RowInfo* info = find_row_info(row);
  return info != nullptr && info->merge == RowMerge::Max;
}

/// a + b, at most UINT64_MAX (counts summed over many shards never wrap).
std::uint64_t saturating_add(std::uint64_t a, std::uint64_t b) {
  return b > std::numeric_limits<std::uint64_t>::max() - a ? std::numeric_limits<std::uint64_t>::max() : a + b;
}

/// One row of a shard's verdict, every field checked (read_row).
struct RowIn {
  std::string tier, name, figure, verdict, detail, tolerances;
  double measured = 0, bound = 0, seconds = 0;
  std::uint64_t judged = 0;
  std::vector<ValidationCause> causes;
};

/// One shard's file, checked (read_shard).
struct ShardIn {
  std::size_t doc = 0;
  int index = 0, count = 0;
  std::int64_t first = 0, last = 0, frames = 0, bodies = 0;
  int every = 1;
  std::string trace, engine, against;
  std::uint64_t trace_bytes = 0;
  Tolerances tol;
  json identity;  ///< the "shard" object without index, first_frame and last_frame
  std::vector<RowIn> rows;
};

const std::string kAllowedDoc = "the --json file of `validate --trace-in TRACE --shard i/N`";

RowIn read_row(const JsonFields& f, const json& row, const std::string& at) {
  RowIn r;
  const auto key = [&](const char* k) -> const json& {
    return f.member(row, at, k, "every key `validate --json` writes (docs/validation-output.md)");
  };
  f.object(row, at);
  r.tier = f.one_of(key("tier"), at + ".tier", tier_names());
  r.name = f.one_of(key("name"), at + ".name", validation_row_names());
  r.figure = f.text(key("figure"), at + ".figure", kMaxName);
  r.measured = f.number_or_null(key("measured"), at + ".measured", -kMaxFigure, kMaxFigure);
  r.bound = f.number_or_null(key("bound"), at + ".bound", -kMaxFigure, kMaxFigure);
  r.verdict = f.one_of(key("verdict"), at + ".verdict", {"pass", "fail", "expected", "n/a"});
  r.detail = f.text(key("detail"), at + ".detail", kMaxText);
  r.judged = f.count(key("judged"), at + ".judged", kMaxCount);
  r.seconds = f.number_or_null(key("seconds"), at + ".seconds", 0, kMaxSeconds);
  r.tolerances = f.text(key("tolerances"), at + ".tolerances", kMaxName);
  std::vector<std::string> names = documented_causes(r.name);
  if (std::find(names.begin(), names.end(), r.name) == names.end()) names.push_back(r.name);
  const json& causes = f.array(key("causes"), at + ".causes", names.size());
  for (std::size_t c = 0; c < causes.size(); ++c) {
    const std::string cat = fmt::format("{}.causes[{}]", at, c);
    const json& cj = f.object(causes[c], cat);
    const auto ckey = [&](const char* k) -> const json& {
      return f.member(cj, cat, k, "every key of a cause (name, unit, count, worst, examples, items, items_complete)");
    };
    ValidationCause vc;
    vc.name = f.one_of(ckey("name"), cat + ".name", names);
    for (const ValidationCause& seen : r.causes)
      if (seen.name == vc.name) f.fail(cat + ".name", "'" + vc.name + "' twice", "each cause once in a row");
    vc.unit = f.text(ckey("unit"), cat + ".unit", kMaxName);
    vc.count = f.count(ckey("count"), cat + ".count", kMaxCount);
    vc.worst = f.number_or_null(ckey("worst"), cat + ".worst", -kMaxFigure, kMaxFigure);
    const json& ex = f.array(ckey("examples"), cat + ".examples", ValidationCause::kMaxExamples);
    for (std::size_t e = 0; e < ex.size(); ++e) {
      const std::string eat = fmt::format("{}.examples[{}]", cat, e);
      const json& x = f.object(ex[e], eat);
      const std::string allowed = "an example {frame, item, figure, text}";
      ValidationExample ve;
      ve.frame = f.integer(f.member(x, eat, "frame", allowed), eat + ".frame", -1,
                           static_cast<std::int64_t>(trace_limits::kMaxFrames));
      ve.item = f.text(f.member(x, eat, "item", allowed), eat + ".item", kMaxName);
      ve.figure = f.number_or_null(f.member(x, eat, "figure", allowed), eat + ".figure", -kMaxFigure, kMaxFigure);
      ve.text = f.text(f.member(x, eat, "text", allowed), eat + ".text", kMaxText);
      vc.examples.push_back(std::move(ve));
    }
    const json& items = f.array(ckey("items"), cat + ".items", ValidationCause::kMaxItems);
    for (std::size_t i = 0; i < items.size(); ++i)
      vc.items.push_back(f.text(items[i], fmt::format("{}.items[{}]", cat, i), kMaxName));
    vc.items_complete = f.boolean(ckey("items_complete"), cat + ".items_complete");
    r.causes.push_back(std::move(vc));
  }
  return r;
}

/// Checks one shard's document: the "shard" object (identity and share) and every row,
/// each field by type and range; InputError naming the file and field.
ShardIn read_shard(const json& d, const std::string& name, std::size_t doc) {
  const JsonFields f("--merge: " + name);
  if (!d.is_object() || !d.contains("shard") || !d["shard"].is_object())
    throw InputError(fmt::format("--merge: {}: no \"shard\" object (not a shard's verdict); allowed: {}", name,
                                 kAllowedDoc));
  const json& s = d["shard"];
  const auto key = [&](const char* k) -> const json& { return f.member(s, "shard", k, kAllowedDoc); };
  ShardIn sh;
  sh.doc = doc;
  sh.count = static_cast<int>(f.integer(key("count"), "shard.count", 1, 100000));
  sh.index = static_cast<int>(f.integer(key("index"), "shard.index", 0, sh.count - 1));
  const auto max_frames = static_cast<std::int64_t>(trace_limits::kMaxFrames);
  sh.frames = f.integer(key("frames"), "shard.frames", 0, max_frames);
  sh.first = f.integer(key("first_frame"), "shard.first_frame", 1, max_frames + 1);
  sh.last = f.integer(key("last_frame"), "shard.last_frame", 0, max_frames);
  sh.bodies = f.integer(key("bodies"), "shard.bodies", 0, static_cast<std::int64_t>(trace_limits::kMaxBodies));
  sh.every = static_cast<int>(f.integer(key("every"), "shard.every", 1, std::numeric_limits<int>::max()));
  sh.trace = f.text(key("trace"), "shard.trace", kMaxName);
  sh.trace_bytes = f.count(key("trace_bytes"), "shard.trace_bytes", std::numeric_limits<std::uint64_t>::max());
  sh.engine = f.text(key("engine"), "shard.engine", kMaxName);
  sh.against = f.one_of(key("against"), "shard.against", {"fcl", "none"});
  const json& tol = f.object(key("tolerances"), "shard.tolerances");
  for (const ToleranceEntry& e : tolerance_table())
    sh.tol.*(e.member) = f.number_or_null(f.member(tol, "shard.tolerances", e.name, "every tolerance by name"),
                                          std::string("shard.tolerances.") + e.name, 0, kMaxFigure);
  for (auto it = tol.begin(); it != tol.end(); ++it)
    if (std::none_of(tolerance_table().begin(), tolerance_table().end(),
                     [&](const ToleranceEntry& e) { return it.key() == e.name; }))
      f.fail("shard.tolerances." + it.key(), "an unknown tolerance", "the tolerances of this octocd");
  for (const ToleranceEntry& e : tolerance_table())
    if (std::isnan(sh.tol.*(e.member)))
      f.fail(std::string("shard.tolerances.") + e.name, "null", "a finite number >= 0");
  const auto want = shard_frames({sh.index, sh.count}, sh.frames);
  if (want.first != sh.first || want.second != sh.last)
    f.fail("shard.first_frame", fmt::format("shard {}/{} holds frames {}..{}, its share of {} frames is {}..{}",
                                            sh.index, sh.count, sh.first, sh.last, sh.frames, want.first, want.second),
           kAllowedDoc);
  sh.identity = s;
  for (const char* k : {"index", "first_frame", "last_frame"}) sh.identity.erase(k);
  const json& rows = f.array(f.member(d, "", "rows", kAllowedDoc), "rows", validation_row_names().size());
  for (std::size_t r = 0; r < rows.size(); ++r) {
    sh.rows.push_back(read_row(f, rows[r], fmt::format("rows[{}]", r)));
    for (std::size_t q = 0; q + 1 < sh.rows.size(); ++q)
      if (sh.rows[q].name == sh.rows.back().name)
        f.fail(fmt::format("rows[{}].name", r), fmt::format("'{}' is also rows[{}]", sh.rows.back().name, q),
               "each row once");
  }
  return sh;
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
    // Strict: a key twice in one object, a NUL byte or more than 64 levels is refused.
    docs.push_back(parse_json_strict(text, "--merge: " + f));
  }
  return merge_validation_docs(docs, files);
}

MergedValidation merge_validation_docs(const std::vector<json>& docs, const std::vector<std::string>& names) {
  if (docs.empty()) throw InputError("--merge: no shard files; allowed: the --json files of every shard 0/N .. N-1/N");
  if (names.size() != docs.size()) throw InputError("--merge: a name for each shard file; allowed: one per file");
  std::vector<ShardIn> shards;
  for (std::size_t k = 0; k < docs.size(); ++k) shards.push_back(read_shard(docs[k], names[k], k));
  // One run: the same trace, engine, frames, checks and tolerances.
  const ShardIn& ref = shards.front();
  for (const ShardIn& sh : shards) {
    if (sh.identity == ref.identity) continue;
    std::string what;
    for (auto it = ref.identity.begin(); it != ref.identity.end(); ++it) {
      const auto other = sh.identity.find(it.key());
      if (other == sh.identity.end() || *other != it.value()) {
        what = fmt::format("{} {} differs from {}'s {}", it.key(), other == sh.identity.end() ? "(missing)" : other->dump(),
                           names[ref.doc], it.value().dump());
        break;
      }
    }
    if (what.empty()) what = fmt::format("its run differs from {}'s", names[ref.doc]);
    throw InputError(fmt::format("--merge: {}: not a shard of the same run: {}; allowed: the shards of one "
                                 "`validate --trace-in TRACE --shard i/N` run (same trace, engine, frames, --every, "
                                 "--against and tolerances)",
                                 names[sh.doc], what));
  }
  std::sort(shards.begin(), shards.end(), [](const ShardIn& a, const ShardIn& b) { return a.index < b.index; });
  for (std::size_t k = 1; k < shards.size(); ++k)
    if (shards[k].index == shards[k - 1].index)
      throw InputError(fmt::format("--merge: {}: shard {}/{} overlaps {} (the same frames {}..{}); allowed: each "
                                   "shard once",
                                   names[shards[k].doc], shards[k].index, shards[k].count, names[shards[k - 1].doc],
                                   shards[k].first, shards[k].last));
  for (int i = 0; i < ref.count; ++i)
    if (std::size_t(i) >= shards.size() || shards[std::size_t(i)].index != i) {
      const auto fr = shard_frames({i, ref.count}, ref.frames);
      std::string given;
      for (const std::string& n : names) given += (given.empty() ? "" : ", ") + n;
      throw InputError(fmt::format("--merge: shard {}/{} (frames {}..{}) is missing among {}; allowed: every shard "
                                   "0/{} .. {}/{}",
                                   i, ref.count, fr.first, fr.second, given, ref.count, ref.count - 1, ref.count));
    }

  MergedValidation m;
  const ShardIn& first_shard = shards.front();
  m.identity.trace = first_shard.trace;
  m.identity.trace_bytes = first_shard.trace_bytes;
  m.identity.engine = first_shard.engine;
  m.identity.bodies = first_shard.bodies;
  m.identity.frames = first_shard.frames;
  m.identity.every = first_shard.every;
  m.identity.against = first_shard.against;
  m.identity.tol = first_shard.tol;
  m.run.trace = m.identity.trace;
  for (const ShardIn& sh : shards) m.files.push_back(names[sh.doc]);

  // Rows: the same rows (name, tier, figure, bound, tolerances) in the same order in every shard.
  const std::vector<RowIn>& rows0 = first_shard.rows;
  for (const ShardIn& sh : shards) {
    bool same = sh.rows.size() == rows0.size();
    for (std::size_t r = 0; same && r < rows0.size(); ++r) {
      const RowIn &a = sh.rows[r], &b = rows0[r];
      same = a.name == b.name && a.tier == b.tier && a.figure == b.figure && a.tolerances == b.tolerances &&
             (a.bound == b.bound || (std::isnan(a.bound) && std::isnan(b.bound)));
    }
    if (!same)
      throw InputError(fmt::format("--merge: {}: its rows differ from {}'s (another octocd build?); allowed: shards "
                                   "of one run",
                                   names[sh.doc], names[first_shard.doc]));
  }
  for (std::size_t r = 0; r < rows0.size(); ++r) {
    ValidationResult out;
    const RowIn& first = rows0[r];
    out.tier = *find_tier(first.tier);  // one of tier_names(), checked on reading
    out.name = first.name;
    out.figure = first.figure;
    out.bound = first.bound;
    out.tolerances = first.tolerances;
    const bool counts = !measures_largest(out.name);
    out.measured = 0;
    out.applicable = false;
    out.pass = true;
    std::string fail_detail, first_detail;
    const std::vector<std::string> documented = documented_causes(out.name);
    std::vector<ValidationCause> causes;
    std::vector<std::set<std::string>> items;
    for (const ShardIn& sh : shards) {
      const RowIn& row = sh.rows[r];
      out.measured = counts ? out.measured + row.measured : std::max(out.measured, row.measured);
      if (std::isnan(row.measured)) out.measured = row.measured;
      out.judged = saturating_add(out.judged, row.judged);
      if (!std::isnan(row.seconds)) out.seconds += row.seconds;
      if (row.verdict != "n/a") out.applicable = true;
      const bool failed = row.verdict == "fail" || row.verdict == "expected";
      if (failed && out.pass) fail_detail = row.detail;
      if (first_detail.empty()) first_detail = row.detail;
      if (failed) out.pass = false;
      if (documented.empty()) continue;  // one cause named like the row: rebuilt
      for (const ValidationCause& c : row.causes) {
        auto it = std::find_if(causes.begin(), causes.end(), [&](const ValidationCause& x) { return x.name == c.name; });
        if (it == causes.end()) {
          ValidationCause nc;
          nc.name = c.name;
          nc.unit = c.unit;
          causes.push_back(nc);
          items.emplace_back();
          it = causes.end() - 1;
        }
        std::set<std::string>& its = items[std::size_t(it - causes.begin())];
        it->count = saturating_add(it->count, c.count);
        it->worst = std::max(it->worst, c.worst);
        it->examples.insert(it->examples.end(), c.examples.begin(), c.examples.end());
        its.insert(c.items.begin(), c.items.end());
        if (!c.items_complete) it->items_complete = false;
      }
    }
    for (std::size_t k = 0; k < causes.size(); ++k) {
      // A finding about the whole trace rather than a frame (every example at frame -1,
      // e.g. momentum-balance's systematic impulse ratio, fitted per shard) counts once per
      // item however many shards report it; its example is the worst shard's.
      std::vector<ValidationExample>& whole = causes[k].examples;
      if (!whole.empty() && causes[k].items_complete &&
          std::all_of(whole.begin(), whole.end(), [](const ValidationExample& e) { return e.frame < 0; })) {
        const std::uint64_t once = items[k].size();
        if (counts && causes[k].count > once) out.measured -= double(causes[k].count - once);
        causes[k].count = std::min<std::uint64_t>(causes[k].count, once);
        std::vector<ValidationExample> worst;
        for (const ValidationExample& e : whole) {
          auto it = std::find_if(worst.begin(), worst.end(), [&](const ValidationExample& w) { return w.item == e.item; });
          if (it == worst.end())
            worst.push_back(e);
          else if (e.figure > it->figure)
            *it = e;
        }
        whole = std::move(worst);
      }
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
