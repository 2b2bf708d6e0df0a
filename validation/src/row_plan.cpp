// What each row of `validate --trace-in` needs of a trace (plan_trace_rows), and the n/a
// that a row needing a quantity the trace lacks gets instead of a verdict
// (apply_trace_plan): docs/validate-your-engine.md, "What a trace must carry".
#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/external.hpp"
#include "octocd/scene.hpp"
#include "octocd/validation_rows.hpp"

namespace octocd {

namespace {

const char* const kStates = "/states/position and /states/velocity";
const char* const kContacts = "/contacts (offsets, pair, normal, depth, jn, jt)";
const char* const kRotation = "/states/orientation and /states/angular_velocity (version 2)";
// The trace declares contacts_complete 0: never advised back to 1 (the writer knows its
// engine drops rows); the rows are judged where the steps or pairs that may lack them are named.
const char* const kContactsComplete =
    "/contacts/incomplete in place of the root attribute contacts_complete = 0 that the trace declares, where the "
    "engine drops rows only on some steps or pairs (K frames, or K x 3 rows (frame, body_a, body_b)): judging a pair "
    "without rows as missing, or a body's velocity change by rows that may be incomplete, would be a false alarm on "
    "any step (free-flight and conservation judge the bodies and groups the geometry shows apart: "
    "docs/validation.md, \"Incomplete contact reporting\")";
const char* const kEveryState =
    "every state (/states/frame 0, 1, 2, ...: octocd run --state-every 1): the row needs each step's states before "
    "and after it, and this trace records a state every few frames";

/// The scene's response.iterations, for a trace read as octocd's conventions (1 without a
/// readable scene: the check-only listing does not judge the scene).
int scene_iterations(const ExternalBodies& bodies) {
  if (bodies.scene_json.empty()) return 1;
  try {
    return parse_embedded_scene(bodies.scene_json, "scene", "").response.iterations;  // no mesh looked up
  } catch (const InputError&) {
    return 1;
  }
}

}  // namespace

std::vector<TraceRowPlan> plan_trace_rows(const ExternalTraceInfo& info, const ExternalBodies& bodies) {
  const PhysicsBodies& p = bodies.physics;
  const bool impulses_complete = info.octocd_conventions ? scene_iterations(bodies) <= 1 : p.impulses_complete;
  std::vector<TraceRowPlan> out;
  for (const RowInfo& row : validation_rows()) {
    TraceRowPlan r;
    r.name = row.name;
    r.tier = row.tier;
    auto needs = [&](bool have, const std::string& what) {
      if (!have && r.judged) {
        r.judged = false;
        r.add = what;
      }
    };
    auto part = [&](bool have, const std::string& what) {
      if (!have && r.judged) r.partial += (r.partial.empty() ? "" : "; ") + what;
    };
    // What the row's table entry says it needs (validation_rows.def), in order; then its own.
    for (const TraceNeed need : row.needs) switch (need) {
        case TraceNeed::Pairs:
          needs(info.has_pairs, "/pairs/offsets and /pairs/pair (the engine's candidate pairs of each step)");
          break;
        case TraceNeed::Contacts:
          needs(info.has_contacts, kContacts);
          break;
        case TraceNeed::CompleteContacts:
          needs(p.contacts_complete, kContactsComplete);
          break;
        case TraceNeed::States:
          needs(info.has_states, kStates);
          break;
        case TraceNeed::EveryState:
          needs(!info.sparse_states, kEveryState);
          break;
      }
    switch (row.id) {
      default:  // the table's needs are all it needs (penetration: poses, states or AABBs, are checked)
        break;
      case RowId::ContactGeometry:
        part(info.has_points, "/contacts/point (version 2) for the check that each row's point lies on both shapes");
        break;
      case RowId::Friction:
        part(!info.sparse_states, "every state (octocd run --state-every 1) for the dissipation; the cone is judged on "
                                  "the steps whose pre-step state is recorded");
        needs(p.impulses == PhysicsBodies::Impulses::Complete,
              fmt::format("nothing: the trace declares impulses = \"{}\" (its rows carry no friction impulse)",
                          impulses_name(p.impulses)));
        part(info.has_jt3 || info.version == 1,
             "/contacts/jt3 (version 2) for the vector rule [rule: jt3]; judged on the scalar jt [rule: scalar]");
        break;
      case RowId::Conservation:
        needs(info.has_contacts, fmt::format("{} (isolated groups are bodies in contact)", kContacts));
        part(info.has_rotation, fmt::format("{} for the angular momentum", kRotation));
        break;
      case RowId::MomentumBalance:
        needs(impulses_complete,
              "nothing: the trace declares impulses_complete = 0 (its rows hold part of the step's impulses)");
        part(info.has_rotation && info.has_points,
             fmt::format("{} and /contacts/point for the angular balance", kRotation));
        // Version 1's jt is along the sliding by its contract; version 2's scalar jt is the
        // component along -v_t, all of the friction only for an engine with one direction.
        needs(p.impulses != PhysicsBodies::Impulses::None,
              "nothing: the trace declares impulses = \"none\" (the engine reports no impulse)");
        needs(info.has_jt3 || info.version == 1 || info.octocd_conventions || p.friction_directions == 1 ||
                  p.impulses == PhysicsBodies::Impulses::NormalOnly,
              "/contacts/jt3 (each row's friction impulse vector), or the root attribute friction_directions = 1 "
              "where each row's friction lies along its sliding: the scalar jt of an engine with two friction "
              "directions leaves the second out");
        part(info.has_jt3 || info.version == 1 || p.impulses == PhysicsBodies::Impulses::NormalOnly,
             "/contacts/jt3 (version 2): the scalar jt leaves each slow row's friction direction open (a disc)");
        break;
      case RowId::FreeFlight:
        needs(info.has_contacts, fmt::format("{}: a body is free in a step without a row (a run without contacts "
                                             "writes /contacts/offsets of zeros and empty rows)",
                                             kContacts));
        part(info.has_rotation, fmt::format("{} for the spin and the orientation", kRotation));
        break;
      case RowId::CandidateSets:
      case RowId::MidphaseCompleteness:
        needs(false, "nothing a trace can add: the row judges octocd's own broadphases and midphase (design.md "
                     "section 5); another engine's pairs are judged by broadphase-completeness");
        break;
      case RowId::Analytic:
      case RowId::BulletDynamics:
        needs(false, "nothing a trace can add: the row steps an engine (octocd validate SCENE.json)");
        break;
      case RowId::NonPenetrationEq14:  // the model tier's response rows (design.md section 6)
      case RowId::FrictionMonotonicity:
      case RowId::ImpulseConservation:
      case RowId::AppliedState:
        needs(info.spec6_response,
              "the root attribute response_model = \"spec6\" (only for an engine that implements design.md section "
              "6's response)");
        needs(info.has_contacts || row.id == RowId::AppliedState, kContacts);
        needs(info.has_states || row.id != RowId::AppliedState, kStates);
        needs(!info.sparse_states, kEveryState);
        break;
    }
    out.push_back(std::move(r));
  }
  return out;
}

void apply_trace_plan(std::vector<ValidationResult>& results, const std::vector<TraceRowPlan>& plan) {
  for (ValidationResult& r : results)
    for (const TraceRowPlan& p : plan) {
      if (p.name != r.name || p.judged) continue;
      if (p.add.rfind("nothing", 0) == 0) break;  // nothing to add: the row's own reason stands
      if (r.applicable) {
        // Never a verdict on an omission: whatever the row computed without the quantity.
        r.applicable = false;
        r.pass = true;
        r.measured = 0;
        r.judged = 0;
        r.causes.clear();
        r.detail = "n/a: the trace lacks what this row needs; to judge it, add " + p.add;
        break;
      }
      if (p.add == kEveryState) {  // sparse states: the row's own "no states" would mislead
        r.detail = std::string("n/a: the trace lacks what this row needs; to judge it, add ") + kEveryState;
        break;
      }
      // Already n/a: its detail names what to add (the dataset, or the attribute's name).
      const std::string attribute = "the root attribute ";
      std::string key = p.add.rfind(attribute, 0) == 0 ? p.add.substr(attribute.size()) : p.add;
      key = key.substr(0, key.find(' '));
      if (r.detail.find(key) == std::string::npos) r.detail += "; to judge it, add " + p.add;
      break;
    }
}

}  // namespace octocd
