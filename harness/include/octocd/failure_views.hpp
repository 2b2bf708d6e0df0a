#pragma once
/// \file failure_views.hpp
/// `octocd validate --view DIR`: a page (octocd/view.hpp) per failing example of a judged
/// trace, and the links to them from the table, the JSON and JUnit (docs/debugging.md).

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/validation.hpp"

namespace octocd {

/// Most pages `validate --view` writes for one run (the failing examples beyond it are
/// counted and said).
constexpr std::size_t kMaxViewPages = 20;

/// One page of a failing example: where it is in the results and where it was written.
struct ViewLink {
  std::size_t row = 0;      ///< index into the results
  std::string row_name;     ///< the row's name
  std::string cause;        ///< the cause's name (failure_causes of the row)
  std::size_t example = 0;  ///< index into the cause's examples
  std::string item;         ///< "pair (A, B)" or "body I"
  std::int64_t frame = 0;   ///< the example's frame
  std::string path;         ///< the page, DIR/NAME.html as DIR was given
};

/// The pages `validate --view` wrote, and one line saying how many, the cap and what was
/// left without a page.
struct FailureViews {
  std::vector<ViewLink> links;
  std::string summary;
  /// The first page that could not be written (the folder refused it: EACCES, ENOSPC, a
  /// target that is not a regular file): the reason, naming the folder; "" when none. No
  /// page is tried after it. The verdict is still printed and written (--json, --junit),
  /// and `validate` then exits 1 with this line.
  std::string write_error;
};

/// `validate --view DIR`: for each failing row's causes (failure_causes), each example
/// that names a frame and a pair or a body gets the page of `trace` at that frame and item
/// in `dir` (row order, at most kMaxViewPages; one per row, cause and item). An example
/// whose page cannot be drawn is counted in the summary, with the first reason; a page that
/// cannot be written ends the pages (FailureViews::write_error) without throwing. `mesh_dir`:
/// ViewSettings::mesh_dir.
FailureViews write_failure_views(const std::string& trace, const std::vector<ValidationResult>& results,
                                 const std::string& dir, const std::string& mesh_dir = "");

/// The table's lines of the pages (after format_results): "  ROW/CAUSE frame F ITEM: PATH".
std::string format_views(const FailureViews& views);

/// A link as seen from the folder of `written_file` (the JSON or JUnit file that holds
/// it), so an artifact folder holding both works wherever it is unpacked.
std::string view_link(const std::string& page, const std::string& written_file);

/// Adds "view": LINK (view_link from `json_file`) to each example of `doc` (results_json)
/// that has a page.
void add_views_to_json(nlohmann::ordered_json& doc, const FailureViews& views, const std::string& json_file);

/// `results` with "; view: LINK" (view_link from `junit_file`) appended to the detail of
/// each row with pages: what JUnit's failure message shows.
std::vector<ValidationResult> with_views_in_details(const std::vector<ValidationResult>& results,
                                                    const FailureViews& views, const std::string& junit_file);

}  // namespace octocd
