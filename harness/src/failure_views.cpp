// `validate --view`: the pages of failing examples and their links (octocd/failure_views.hpp).
#include "octocd/failure_views.hpp"

#include <filesystem>
#include <regex>
#include <set>

#include <fmt/format.h>

#include "octocd/atomic_file.hpp"
#include "octocd/error.hpp"
#include "octocd/expect.hpp"
#include "octocd/view.hpp"

namespace octocd {

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

}  // namespace octocd
