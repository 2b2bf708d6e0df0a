#pragma once
/// \file validation_rows.hpp
/// Every validator row's identity, in one table (octocd/validation_rows.def; design.md
/// sections 7, 13b.13): its name, its tier, its documented causes (the names an
/// expectation's "cause" takes, the items each counts and its unit) and how `validate
/// --merge` joins its figure across shards; RowId is generated from the same table.
/// The physics tier's table, the model tier, expectations (octocd/expect.hpp), the trace
/// plan (octocd/external.hpp) and the merge (octocd/shards.hpp) all read it; a row is added
/// to validation_rows.def once. What a row measures, its figure and its tolerances stay
/// with its judge.

#include <string>
#include <vector>

#include "octocd/validation.hpp"

namespace octocd {

/// The rows, in the order `validate` reports them: the physics tier, then the model tier;
/// one per entry of octocd/validation_rows.def.
enum class RowId {
#define OCTOCD_ROW(id, name, tier, merge, causes, needs, frames) id,
#include "octocd/validation_rows.def"
#undef OCTOCD_ROW
};

/// How `validate --merge` joins a row's `measured` over the shards of one run.
enum class RowMerge {
  /// `measured` counts failing items (bound 0): the shards' counts add up.
  Sum,
  /// `measured` is the largest figure judged (the worst normal angle, the deepest
  /// penetration, a rerun's worst error): the largest of the shards'.
  Max,
};

/// One documented cause of a row's failures (design.md section 13b.13).
struct RowCause {
  const char* name;   ///< kebab-case, unique within its row: an expectation's "cause"
  const char* items;  ///< what its judged count counts, for the row's detail ("required pairs"); "" when unnamed
  const char* unit;   ///< the unit of its figures ("m", "deg", "of bound", ...)
};

/// What a row needs of a trace to judge it (validation_rows.def's NEEDS; `--check-only`'s
/// plan: octocd/row_plan.hpp).
enum class TraceNeed {
  Pairs,             ///< /pairs (the engine's candidate pairs of each step)
  Contacts,          ///< /contacts (offsets, pair, normal, depth, jn, jt)
  CompleteContacts,  ///< the root attribute contacts_complete = 1
  States,            ///< /states/position and /states/velocity
  EveryState,        ///< a state every frame (state_every 1)
};

/// One row's identity.
struct RowInfo {
  RowId id;                     ///< its place in validation_rows()
  const char* name;             ///< e.g. "contact-geometry": ValidationResult::name, an expectation's "row"
  Tier tier;                    ///< the judge it belongs to
  RowMerge merge;               ///< how shards' figures join
  std::vector<RowCause> causes; ///< its causes in their documented order; empty: it does not split its failures
  std::vector<TraceNeed> needs; ///< what it needs of a trace, in order (further needs: row_plan.cpp)
};

/// Every row, in RowId order (physics tier, then model tier): validation_rows.def's entries.
const std::vector<RowInfo>& validation_rows();

/// The row `id`.
const RowInfo& row_info(RowId id);

/// The row named `name`, or nullptr for a name no row has (a shard file of another build).
const RowInfo* find_row_info(const std::string& name);

/// The result of row `id` that does not apply (n/a, never a verdict): its tier and name,
/// `figure` (what the row measures) and `why` as the detail.
ValidationResult not_applicable(RowId id, const char* figure, const std::string& why);

}  // namespace octocd
