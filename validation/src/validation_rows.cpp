/// \file validation_rows.cpp
/// The table of validator rows (octocd/validation_rows.hpp), from octocd/validation_rows.def.

#include "octocd/validation_rows.hpp"

namespace octocd {

// OCTOCD_ROW_CAUSES (A, B): the causes (or needs) A, B of a row as one braced list ({} for none).
#define OCTOCD_ROW_CAUSES(...) {__VA_ARGS__}

const std::vector<RowInfo>& validation_rows() {
  static const std::vector<RowInfo> rows = {
#define OCTOCD_ROW(id, name, tier, merge, causes, needs, frames)                                  \
  {RowId::id, name, Tier::tier, RowMerge::merge, std::vector<RowCause> OCTOCD_ROW_CAUSES causes, \
   std::vector<TraceNeed> OCTOCD_ROW_CAUSES needs},
#include "octocd/validation_rows.def"
#undef OCTOCD_ROW
  };
  return rows;
}

const RowInfo& row_info(RowId id) { return validation_rows()[static_cast<std::size_t>(id)]; }

ValidationResult not_applicable(RowId id, const char* figure, const std::string& why) {
  ValidationResult r;
  r.tier = row_info(id).tier;
  r.name = row_info(id).name;
  r.figure = figure;
  r.applicable = false;
  r.detail = why;
  return r;
}

const RowInfo* find_row_info(const std::string& name) {
  for (const RowInfo& r : validation_rows())
    if (name == r.name) return &r;
  return nullptr;
}

}  // namespace octocd
