// `octocd view` and `validate --view` (cli/view.hpp; the page itself: octocd/view.hpp).
#include "view.hpp"
#include "tools.hpp"

#include <cstdio>
#include <filesystem>
#include <regex>
#include <set>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/expect.hpp"
#include "octocd/view.hpp"

namespace octocd::cli {

namespace {

/// "A,B" into two body indices; InputError naming --pair otherwise.
void parse_pair(const std::string& text, ViewSettings& s) {
  static const std::regex form(R"(^\s*(\d{1,10})\s*,\s*(\d{1,10})\s*$)");
  std::smatch m;
  const auto bad = [&] {
    return InputError(fmt::format("--pair: '{}'; allowed: two body indices A,B (e.g. --pair 3,7)", text));
  };
  if (!std::regex_match(text, m, form)) throw bad();
  const unsigned long long a = std::stoull(m[1].str()), b = std::stoull(m[2].str());
  if (a > 0xffffffffull || b > 0xffffffffull) throw bad();
  s.has_pair = true;
  s.pair_a = static_cast<std::uint32_t>(a);
  s.pair_b = static_cast<std::uint32_t>(b);
}

}  // namespace

struct ViewCommand::Impl {
  CLI::App* cmd = nullptr;
  std::string trace, pair, out, mesh_dir;
  std::int64_t frame = 0;
  std::int64_t body = -1;
  int window = 5;
};

ViewCommand::ViewCommand(CLI::App& app) : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.cmd = app.add_subcommand(
      "view",
      "Draw a frame of a trace on one self-contained HTML page (three.js inlined; no network, no server): the posed "
      "shapes near a pair or a body, their world AABBs, the engine's contact points and normals beside the "
      "physics tier's reference (SAT or FCL), with a frame slider (docs/debugging.md)");
  s.cmd->add_option("trace", s.trace,
                    "Trace (HDF5): octocd's (any --state-every: a frame without its own state is drawn at the "
                    "nearest recorded one) or an external trace (versions 1 and 2), read through the hardened reader")
      ->required();
  s.cmd->add_option("--frame", s.frame, "The frame shown first (1 .. the trace's frames; default: the first frame with a contact, else 1)");
  s.cmd->add_option("--pair", s.pair, "The item: a pair of bodies A,B (drawn with the bodies near it)");
  s.cmd->add_option("--body", s.body, "The item: one body I (drawn with the bodies near it)");
  s.cmd->add_option("--window", s.window,
                    fmt::format("Frames each side of --frame on the slider (0 .. {})", kMaxWindow))
      ->default_val(5);
  s.cmd->add_option("-o,--out", s.out, "Folder the page is written into (created when absent)")->required();
  s.cmd->add_option("--mesh-dir", s.mesh_dir,
                    "The only folder (besides the data dir) where the mesh files named by the trace's scene are looked "
                    "up (default: the trace's folder)");
}

ViewCommand::~ViewCommand() = default;

bool ViewCommand::selected() const { return impl_->cmd->parsed(); }

int ViewCommand::run() {
  const Impl& s = *impl_;
  ViewSettings vs;
  if (s.cmd->get_option("--frame")->count() > 0 && s.frame < 1)
    throw InputError(fmt::format("--frame: {}: outside the trace; allowed: 1 .. the trace's frames", s.frame));
  vs.frame = s.frame;
  vs.window = s.window;
  vs.mesh_dir = s.mesh_dir;
  if (!s.pair.empty()) parse_pair(s.pair, vs);
  if (s.cmd->get_option("--body")->count() > 0) {
    if (s.body < 0 || s.body > 0xffffffffll)
      throw InputError(fmt::format("--body: {}: does not exist; allowed: a body index 0 .. bodies - 1", s.body));
    vs.has_body = true;
    vs.body = static_cast<std::uint32_t>(s.body);
  }
  check_output_folder(s.out, "-o", false);  // before the trace is read
  const ViewPage page = write_view(s.trace, vs, s.out);
  fmt::print("wrote {} ({} bytes): frame {}, {} bodies, {} frames on the slider{}\n", page.path, page.bytes,
             page.frame, page.bodies, page.frames, page.note.empty() ? "" : "; note: " + page.note);
  return 0;
}

FailureViews write_failure_views(const std::string& trace, const std::vector<ValidationResult>& results,
                                 const std::string& dir, const std::string& mesh_dir) {
  static const std::regex pair_item(R"(^pair \((\d+), (\d+)\)$)"), body_item(R"(^body (\d+)$)");
  FailureViews out;
  std::size_t over_cap = 0, undrawable = 0;
  std::set<std::string> names;
  std::string first_error;
  for (std::size_t ri = 0; ri < results.size() && out.write_error.empty(); ++ri) {
    const ValidationResult& r = results[ri];
    for (const ValidationCause& c : failure_causes(r)) {
      for (std::size_t xi = 0; xi < c.examples.size() && out.write_error.empty(); ++xi) {
        const ValidationExample& x = c.examples[xi];
        std::smatch m;
        ViewSettings vs;
        if (x.frame >= 1 && std::regex_match(x.item, m, pair_item)) {
          vs.has_pair = true;
          vs.pair_a = static_cast<std::uint32_t>(std::stoul(m[1].str()));
          vs.pair_b = static_cast<std::uint32_t>(std::stoul(m[2].str()));
        } else if (x.frame >= 1 && std::regex_match(x.item, m, body_item)) {
          vs.has_body = true;
          vs.body = static_cast<std::uint32_t>(std::stoul(m[1].str()));
        } else {
          ++undrawable;
          continue;
        }
        const std::string name = fmt::format("{}-{}-f{}-{}.html", r.name, c.name, x.frame,
                                             vs.has_pair ? fmt::format("pair-{}-{}", vs.pair_a, vs.pair_b)
                                                         : fmt::format("body-{}", vs.body));
        if (names.count(name)) continue;  // the same item again under this cause
        if (out.links.size() >= kMaxViewPages) {
          ++over_cap;
          continue;
        }
        names.insert(name);
        vs.frame = x.frame;
        vs.mesh_dir = mesh_dir;
        vs.row = r.name;
        vs.cause = c.name;
        vs.unit = c.unit;
        vs.figure = x.figure;
        vs.file_name = name;
        try {
          const std::string planted = output_path_kind((std::filesystem::path(dir) / name).string());
          if (!planted.empty())
            throw RuntimeError(fmt::format("view: {}: {}, not a regular file", (std::filesystem::path(dir) / name).string(),
                                           planted));
          const ViewPage page = write_view(trace, vs, dir);
          out.links.push_back(ViewLink{ri, r.name, c.name, xi, x.item, x.frame, page.path});
        } catch (const RuntimeError& e) {  // writing it failed: no page is tried after it
          out.write_error = fmt::format("--view {}: a page cannot be written ({}); the verdict is complete without "
                                        "its pages",
                                        dir, e.what());
        } catch (const InputError& e) {
          ++undrawable;
          if (first_error.empty()) first_error = e.what();
        }
      }
    }
  }
  out.summary = fmt::format("view: {} page(s) of failing examples in {} (cap {} pages)", out.links.size(), dir,
                            kMaxViewPages);
  if (over_cap > 0) out.summary += fmt::format("; {} more example(s) beyond the cap have no page", over_cap);
  if (undrawable > 0)
    out.summary += fmt::format("; {} example(s) name no frame with a pair or body{}", undrawable,
                               first_error.empty() ? "" : " or could not be drawn (first: " + first_error + ")");
  return out;
}

std::string format_views(const FailureViews& views) {
  std::string text = views.summary + "\n";
  for (const ViewLink& l : views.links)
    text += fmt::format("  {}/{} frame {} {}: {}\n", l.row_name, l.cause, l.frame, l.item, l.path);
  return text;
}

std::string view_link(const std::string& page, const std::string& written_file) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path base = fs::absolute(fs::path(written_file), ec).parent_path().lexically_normal();
  const fs::path rel = fs::absolute(fs::path(page), ec).lexically_normal().lexically_relative(base);
  return rel.empty() ? page : rel.generic_string();
}

void add_views_to_json(nlohmann::ordered_json& doc, const FailureViews& views, const std::string& json_file) {
  if (!doc.contains("rows")) return;
  for (const ViewLink& l : views.links) {
    if (l.row >= doc["rows"].size()) continue;
    for (auto& c : doc["rows"][l.row]["causes"])
      if (c["name"] == l.cause && l.example < c["examples"].size())
        c["examples"][l.example]["view"] = view_link(l.path, json_file);
  }
}

std::vector<ValidationResult> with_views_in_details(const std::vector<ValidationResult>& results,
                                                    const FailureViews& views, const std::string& junit_file) {
  std::vector<ValidationResult> out = results;
  for (const ViewLink& l : views.links)
    if (l.row < out.size()) out[l.row].detail += fmt::format("; view: {}", view_link(l.path, junit_file));
  return out;
}

}  // namespace octocd::cli
