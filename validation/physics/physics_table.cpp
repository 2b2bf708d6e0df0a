// The physics tier's table (physics_impl.hpp): the rows' sums (RowSums), observe()'s calls
// of every physics row's measure and results()' of every row's table entry, in
// validation_rows.def's order. Nothing here names a row: each row's measure and table
// entry sit in its own file.
#include <cstring>
#include <stdexcept>

#include "../src/row_clock.hpp"
#include "physics_impl.hpp"

namespace octocd {

namespace physics_detail {

const char* const kNoChecked =
    "no checked frame with poses (AABBs or detection poses; a trace: add /states/position and /states/velocity, or "
    "/aabbs/min and /aabbs/max)";

std::vector<RowSums> make_row_sums() {
  std::vector<RowSums> sums(validation_rows().size());
  for (const RowInfo& row : validation_rows()) sums[std::size_t(row.id)].causes.resize(row.causes.size());
  return sums;
}

std::size_t cause_index(RowId id, const char* name) {
  const RowInfo& row = row_info(id);
  for (std::size_t k = 0; k < row.causes.size(); ++k)
    if (std::strcmp(row.causes[k].name, name) == 0) return k;
  throw std::logic_error(
      fmt::format("physics table: row {} has no cause \"{}\" (validation_rows.def)", row.name, name));
}

void fill_causes(ValidationResult& r, const RowInfo& row, const std::vector<const Tally*>& tallies) {
  if (tallies.size() != row.causes.size())
    throw std::logic_error(fmt::format("physics table: row {} has {} causes, given {} tallies", row.name,
                                       row.causes.size(), tallies.size()));
  std::string list;
  std::uint64_t failing = 0, judged = 0;
  const RowCause* c = row.causes.data();
  for (const Tally* t : tallies) {
    judged += t->checks;
    if (t->failures) {
      r.causes.push_back(t->cause(c->name, c->unit));
      ++failing;
    }
    list += (list.empty() ? "" : "; ") + t->summary(c->name, c->items, c->unit);
    ++c;
  }
  r.judged = judged;
  if (failing) {
    r.pass = false;
    r.detail += "; causes: " + list;
  }
}

}  // namespace physics_detail

using namespace physics_detail;

ValidationResult PhysicsValidators::Impl::start_row(RowId id, const char* figure, const char* tolerances) {
  const RowInfo& info = row_info(id);
  ValidationResult r;
  r.tier = info.tier;
  r.name = info.name;
  r.figure = figure;
  r.tolerances = tolerances;
  return r;
}

ValidationResult PhysicsValidators::Impl::failures_row(RowId id, const char* figure, const char* tolerances) const {
  ValidationResult r = start_row(id, figure, tolerances);
  std::uint64_t failures = 0;
  for (const Tally& t : sums(id).causes) failures += t.failures;
  r.measured = double(failures);
  r.pass = r.measured == 0;
  return r;
}

void PhysicsValidators::Impl::fill_causes(ValidationResult& r, RowId id) const {
  std::vector<const Tally*> tallies;
  for (const Tally& t : sums(id).causes) tallies.push_back(&t);
  physics_detail::fill_causes(r, row_info(id), tallies);
}

// Every physics row of validation_rows.def, in its order, on its row's clock: its measure
// of every frame, or its judgement of a checked frame's candidates and reference geometry
// (computed by the first row that asks, on its clock); with a judge device, a row that
// judges the device's geometry (judge_device true: device_checked) needs no CheckedFrame.
void PhysicsValidators::Impl::measure_rows(PhysicsFrame& f) {
#define OCTOCD_PHYSICS_EVERY(id)             \
  {                                          \
    RowClock clock(sums(RowId::id).seconds); \
    measure<RowId::id>(f);                   \
  }
#define OCTOCD_PHYSICS_CHECKED(id)                                                \
  {                                                                               \
    RowClock clock(sums(RowId::id).seconds);                                      \
    bool judged = false;                                                          \
    if (device)                                                                   \
      if (DeviceCheckedFrame* d = device_checked(f)) judged = judge_device<RowId::id>(*d); \
    if (!judged)                                                                  \
      if (CheckedFrame* c = checked(f)) judge<RowId::id>(*c);                     \
  }
#include "physics_rows.inc"
}

// Every physics row of validation_rows.def, in its order: its table entry and its time.
std::vector<ValidationResult> PhysicsValidators::results() const {
  const Impl& s = *impl_;
  std::vector<ValidationResult> out;
#define OCTOCD_PHYSICS_EVERY(id)       \
  out.push_back(s.table<RowId::id>()); \
  out.back().seconds = s.sums(RowId::id).seconds;
#define OCTOCD_PHYSICS_CHECKED(id) OCTOCD_PHYSICS_EVERY(id)
#include "physics_rows.inc"
  return out;
}

}  // namespace octocd
