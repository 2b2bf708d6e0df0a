#pragma once
/// \file feasibility.hpp
/// The physics tier's row 9, impulse feasibility (docs/validation.md, "Motion explained by
/// feasible contact impulses"), in three parts: the row's measure and table entry
/// (feasibility.cpp: each checked step's candidates, islands and tallies), the contact
/// points octocd finds on the posed shapes (feasibility_contacts.cpp, with the plane
/// geometry of feasibility_geometry.hpp) and each island's linear programme solved with
/// COIN-OR CLP (feasibility_programme.cpp). Internal to validation/physics.
#include <cstddef>
#include <cstdint>
#include <deque>
#include <limits>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "physics_impl.hpp"
#include "feasibility_geometry.hpp"

namespace octocd::feasibility {

using dmath::D3;

/// Islands with more dynamic bodies than this are not judged (counted and named): the
/// programme has 3-6 rows a body and 8 columns a contact point.
constexpr std::size_t kMaxIslandBodies = 16;
/// Projected Gauss-Seidel sweeps over an island's contact points that find its witness
/// impulses (feasibility_programme.cpp, witness_figure), at most.
constexpr int kWitnessSweeps = 16;
/// Islands of a step whose programmes are solved first beside those without a witness
/// within the bound: the ones with the largest witness figures (their programmes' figures
/// set the threshold below which the others' witnesses stand).
constexpr std::size_t kProbeIslands = 64;
/// Consecutive islands judged by one call of feasibility_islands (on one thread), at most:
/// the first programmes of the small ones among them are solved as one
/// (feasibility_programme.cpp); fewer where a step's islands would make fewer than
/// kMinIslandRuns such runs (the threads' share of a step of a few hundred islands).
constexpr std::size_t kIslandsPerSolve = 32;
constexpr std::size_t kMinIslandRuns = 64;
/// Friction-cone generators per contact point: the cone mu is replaced by the pyramid of
/// kConeSides sides circumscribed about it (every feasible friction impulse stays feasible;
/// the pyramid reaches 1 / cos(pi / kConeSides) = 1.082 mu along its edges).
constexpr int kConeSides = 8;
/// The most earlier steps whose poses the row keeps to find the normals a persistent manifold
/// point may still carry (a persistent point keeps the normal it was found with while the
/// bodies turn: Bullet), and the most poses kept in all (bodies x steps: 2^21, 64 MiB).
constexpr std::size_t kMaxPastSteps = 64;
constexpr std::size_t kMaxPastPoses = std::size_t(1) << 21;
/// The most pairs of edges (one of each hull near the contact) examined for edge crossings
/// on hulls too large for the separating-axis test: a box against a tessellated ball has a
/// few dozen; two finely tessellated hulls resting on each other have thousands, their
/// patch's outline is found without them.
constexpr std::size_t kMaxCrossingWork = 256;
/// How far an engine's own normal may lie from octocd's (deg): an engine queries the shapes
/// its own way (Jolt's normals lie up to 1.17 deg from a fresh query of the same pair).
/// Every normal within it is admitted by widening each cone (feasibility_programme.cpp).
constexpr double kNormalSlackDeg = 1.5;
/// The same slack where the normal is the posed reference's (FCL / libccd EPA on hulls too
/// large for the separating-axis test here, or a mesh): Bullet's bunny-stack-50 takes a
/// normal beyond 1.5 deg of it (frame 292, pair (31, 40)).
constexpr double kPosedNormalSlackDeg = 5.0;

/// One contact of a pair as the programme reads it: the pair's impulse acts on A at `point`
/// and on B at `point_b` (world, m: the same point, unless a contact row of the trace gives
/// the engine's two witness points, /contacts/point_b), along generators about `normal`
/// (unit, B to A), with the pair's friction coefficient.
struct Contact {
  Pair pair;
  D3 point, normal;
  double mu = 0;
  double lever = 0;  ///< how far the engine's point may lie from `point` (m)
  double slack_deg = kNormalSlackDeg;  ///< how far the engine's normal may lie from `normal`
  D3 point_b = point;                  ///< where B takes the impulse (m, world)
  /// Where body `i` (A or B of the pair) takes the impulse.
  const D3& point_of(std::uint32_t i) const { return i == pair.a ? point : point_b; }
};

/// One candidate pair's contacts found on the posed shapes, with its counts.
struct PairContacts {
  std::vector<Contact> contacts;
  std::uint64_t persisted = 0, crossings = 0, crossings_skipped = 0, witness = 0;
  std::size_t persisted_steps = 0;
  /// Empties the contacts (keeping their memory) and zeroes the counts.
  void clear() {
    contacts.clear();
    persisted = crossings = crossings_skipped = witness = 0;
    persisted_steps = 0;
  }
};

/// What became of an island: judged (figure and body), or counted and not judged.
enum class Outcome { Judged, Asleep, Locked, Clamped, TooLarge, Unsolved };
/// A pass of feasibility_islands: the islands' outcomes and witness figures, or their
/// programmes solved.
enum class IslandPass : int { Witness, Programme };
/// An island's verdict (PhysicsValidators::Impl::feasibility_islands): its figure (the
/// largest residual in units of its bound of the impulses found, <= 1 passes), the body
/// named, and the failure's text where figure > 1.
struct IslandVerdict {
  Outcome outcome = Outcome::Judged;
  double figure = 0;
  /// The figure of the island's witness impulses (infinity: none).
  double witness = std::numeric_limits<double>::infinity();
  std::uint32_t body = 0;
  std::string text;
};

/// The row's counts beyond its tally (PhysicsValidators::Impl::row_state).
struct FeasibilityState {
  std::uint64_t steps = 0, islands = 0, contacts = 0, pairs = 0;
  std::uint64_t too_large = 0, asleep = 0, clamped = 0, locked = 0, unsolved = 0;
  /// Islands whose witness figure stood (their programmes not solved).
  std::uint64_t witnessed = 0;
  std::string too_large_first, unsolved_first;
  std::size_t largest = 0;
  /// The detection poses of the steps before this one (most recent first, consecutive
  /// frames, at most kMaxPastSteps and kMaxPastPoses in all), and the frame of the first.
  std::deque<std::vector<Pose>> past;
  std::int64_t past_frame = -1;
  /// Each hull's edges and supporting planes (HullEdges), found once.
  std::map<const HullFeatures*, feasibility_geometry::HullEdges> hulls;
  std::uint64_t crossings = 0;  ///< contact points on an edge of one hull within reach of the other
  std::uint64_t crossings_skipped = 0;  ///< pair-steps above kMaxCrossingWork
  std::uint64_t witness = 0;  ///< contact points at a row's two witness points (/contacts/point_b)
  std::uint64_t persisted = 0;  ///< contact points given normals of their earlier steps
  std::size_t persisted_steps = 0;  ///< the most earlier steps a point's normals came from
  /// exact_pairs' tables of the step's candidate search, kept from step to step.
  ExactPairsTables pair_tables;
  /// The step's per-body tables (n entries each: the contact graph's components and the
  /// bodies touched, each root's island), rewritten every step in memory kept from step to
  /// step.
  Components components;
  std::vector<std::int32_t> island_of;
  /// The step's contacts per candidate pair, and each island's bodies and contacts, in
  /// memory kept from step to step (at 240,000 pairs a step, freeing their lists was about
  /// as many instructions as the rest of the row).
  std::vector<PairContacts> pair_out;
  std::vector<std::vector<std::uint32_t>> island_members;
  std::vector<std::vector<Contact>> island_contacts;
  /// The step's reach (step_reach_boxes: each body's motion, world and grown boxes) and
  /// pairs within it where the checked frame does not hold them (a judge device's frames),
  /// and the islands' index (the pairs with contacts, the bodies touched, the islands'
  /// roots, the grouping's scratch, the ranges and lists of each island's bodies and pairs)
  /// and verdicts, in memory kept from step to step (at 10^6 bodies the boxes are 56 MB a
  /// step: fresh pages, zeroed on one thread, took longer than filling them on all).
  std::vector<double> motion;
  std::vector<Aabb> world, grown;
  std::vector<Pair> cand;
  std::vector<std::size_t> with_contacts, member_first, pair_first, pairs_flat;
  std::vector<std::uint32_t> bodies_touched, roots, members_flat;
  GroupScratch group_scratch;
  GroupedItems grouped;
  std::vector<IslandVerdict> verdicts;
};


/// What the contact search of one step reads (PhysicsValidators::Impl::feasibility_contacts):
/// the row's state (its earlier poses; the hulls' edges, found once under `hulls_mutex` by
/// whichever thread needs them first), each body's detection pose, world AABB (exact, or the
/// engine's under contact_geometry "aabb") and motion through the step (m); the step's
/// record and, where its contact rows carry two witness points (FrameRecord::point_b), those
/// rows by pair (sorted; empty otherwise).
struct ContactSearch {
  FeasibilityState& st;
  std::mutex& hulls_mutex;
  const std::vector<Pose>& det;
  const std::vector<Aabb>& world;
  const std::vector<double>& motion;
  const FrameRecord& rec;
  const std::vector<std::pair<Pair, std::size_t>>& witness_rows;
};


}  // namespace octocd::feasibility
