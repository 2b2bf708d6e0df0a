// The per-frame validators, fed one FrameRecord at a time: from an octocd engine, from
// another engine through the C++ API (external.cpp) or from an external trace. The
// physics tier (design.md section 13: any engine, posed shapes, FCL) lives in validation/physics/ and
// is called from here; this file holds the model tier's per-frame rows (design.md section 7 items 1,
// 2, 4-6 and 9 as the paper's model defines them), judged for octocd's engines and for
// another engine only when it claims design.md section 6.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <array>
#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "octocd/broadphase_registry.hpp"
#include "octocd/error.hpp"
#include "octocd/exact_pairs.hpp"
#include "octocd/device_judge.hpp"
#include "octocd/physics.hpp"
#include "octocd/reference_contact.hpp"
#include "octocd/validation.hpp"
#include "octocd/validation_rows.hpp"

#include "applied_state.hpp"
#include "../physics/dmath.hpp"
#include "../src/parallel.hpp"
#include "../src/row_clock.hpp"

namespace octocd {

namespace {

/// Signed overlap of two boxes along `axis` (Eq. 9); negative when apart.
double overlap_along(const Aabb& a, const Aabb& b, int axis) {
  return static_cast<double>(std::min(a.max[axis], b.max[axis])) -
         static_cast<double>(std::max(a.min[axis], b.min[axis]));
}

Aabb shifted(const Aabb& box, Vec3 d) { return {box.min + d, box.max + d}; }

double norm(double x, double y, double z) { return std::sqrt(x * x + y * y + z * z); }

/// Tangential part of v relative to n.
Vec3 tangential(Vec3 v, Vec3 n) { return v - dot(v, n) * n; }

/// Mesh vertices (world) of `s` lying within `margin` of the world box `other`.
std::vector<Vec3> candidates(const PlacedShape& s, const Aabb& other, float margin) {
  std::vector<Vec3> out;
  const Aabb e = expanded(other, margin);
  for (const Vec3& v : s.octree->vertices) {
    const Vec3 w = v + s.position;
    if (contains(e, Aabb{w, w})) out.push_back(w);
  }
  return out;
}

/// The exhaustive vertex test (design.md section 5.3) over candidate vertices only: a vertex farther
/// than theta from the other body's AABB cannot be within theta of any of its vertices,
/// so dropping it changes nothing; no tree or grid prunes the remaining pairs. Its answer is
/// that of testing every remaining pair with length2(u - w) < theta^2 in float: B's vertices
/// sorted by x, each vertex of A computes only the pairs whose float difference along x is
/// below |theta| in magnitude. Every other pair has dx * dx >= theta^2 before rounding, so
/// its float length2 (rounding is monotone, the other two squares are >= 0) is >= theta^2 as
/// rounded: it cannot answer yes. Non-finite coordinates: every pair, as written.
bool exhaustive_oracle(const PlacedShape& a_in, const PlacedShape& b_in, float theta) {
  if (!a_in.octree || !b_in.octree) return exhaustive_contact(a_in, b_in, theta);
  const float margin = 1.01f * theta + 1e-6f;
  const std::vector<Vec3> ca = candidates(a_in, b_in.box, margin);
  if (ca.empty()) return false;
  std::vector<Vec3> cb = candidates(b_in, a_in.box, margin);
  const float theta2 = theta * theta;
  const auto finite = [](const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); };
  if (!std::all_of(ca.begin(), ca.end(), finite) || !std::all_of(cb.begin(), cb.end(), finite)) {
    for (const Vec3& u : ca)
      for (const Vec3& w : cb)
        if (length2(u - w) < theta2) return true;
    return false;
  }
  const float reach = std::fabs(theta);
  std::sort(cb.begin(), cb.end(), [](const Vec3& p, const Vec3& q) { return p.x < q.x; });
  for (const Vec3& u : ca) {
    // u.x - w.x does not rise as w.x rises: the pairs within reach along x are one run.
    auto w = std::partition_point(cb.begin(), cb.end(), [&](const Vec3& q) { return u.x - q.x >= reach; });
    for (; w != cb.end() && u.x - w->x > -reach; ++w)
      if (length2(u - *w) < theta2) return true;
  }
  return false;
}

/// bp->find_pairs(boxes, out) on a helper thread while this one polls `stop` every 10 ms:
/// one call of an O(n^2) broadphase (flat, fcl-naive) on 10^5 bodies takes minutes and
/// polls nothing. A stop throws ValidationStopped at once and leaves the helper to finish
/// on its own: it owns a copy of the boxes, a share of the broadphase and its result (the
/// process ends it when it exits). Without `stop`, a plain call. Its loops on the worker team
/// use `threads` (0: default_threads()). Rethrows its errors.
void find_pairs_stoppable(const std::shared_ptr<BroadPhase>& bp, const std::vector<Aabb>& boxes,
                          std::vector<Pair>& out, const std::function<bool()>& stop, int threads = 0) {
  BroadPhaseStats stats;
  if (!stop) {
    const ThreadCount at(threads);
    bp->find_pairs(boxes, out, stats);
    return;
  }
  if (stop()) throw ValidationStopped();
  struct Job {
    std::shared_ptr<BroadPhase> bp;
    std::vector<Aabb> boxes;
    std::vector<Pair> pairs;
    std::exception_ptr error;
    std::mutex m;
    std::condition_variable cv;
    bool done = false;
  };
  auto job = std::make_shared<Job>();
  job->bp = bp;
  job->boxes = boxes;
  job->pairs.swap(out);  // keep its capacity
  std::thread([job, threads] {
    try {
      const ThreadCount at(threads);
      BroadPhaseStats st;
      job->bp->find_pairs(job->boxes, job->pairs, st);
    } catch (...) {
      job->error = std::current_exception();
    }
    const std::lock_guard<std::mutex> lock(job->m);
    job->done = true;
    job->cv.notify_all();
  }).detach();
  std::unique_lock<std::mutex> lock(job->m);
  while (!job->cv.wait_for(lock, std::chrono::milliseconds(10), [&] { return job->done; }))
    if (stop()) throw ValidationStopped();
  if (job->error) std::rethrow_exception(job->error);
  out.swap(job->pairs);
}

/// AABB tests a quadratic-cost broadphase (BroadPhaseCost::quadratic, e.g. fcl-naive) may
/// make on one judged frame before it is compared on every k-th judged frame only, k =
/// ceil(n(n-1)/2 / this): about 0.25 s of one core (FCL's naive manager tests a pair in about
/// 12 ns). Its comparisons stay spread over the whole run; the row's detail names the stride.
constexpr double kQuadraticTestsPerJudgedFrame = 2e7;

/// The most AABB tests one call of a quadratic-cost broadphase may make for it to be compared
/// at all: about two minutes of one core, up to 141,421 boxes. Above it one call is a judged
/// frame of hours (10^6 boxes: 5 x 10^11 tests), which no stride spreads: such a broadphase
/// is not compared, and the row's detail says so.
constexpr double kQuadraticTestsPerCall = 1e10;

/// The AABB tests of one call of a quadratic-cost broadphase on `n` boxes, n(n-1)/2.
double quadratic_tests(std::size_t n) {
  return 0.5 * static_cast<double>(n) * static_cast<double>(n > 0 ? n - 1 : 0);
}

/// Whether a broadphase of cost `cost` is compared at all on `n` boxes.
bool comparable(BroadPhaseCost cost, std::size_t n) {
  return cost != BroadPhaseCost::quadratic || quadratic_tests(n) <= kQuadraticTestsPerCall;
}

/// The most boxes a subquadratic broadphase is compared on in every judged frame: above, it
/// is compared once in ceil(n / this) judged frames from the first. octocd's three CPU
/// broadphases take about 0.2 s together on 16 threads at 10^6 boxes (`validate
/// boxes-uniform-1m --engine cuda --frames 300 --every 1` on the H200 host: candidate-sets
/// 9.9-12.2 s over 50 compared frames), so boxes-uniform-1m's 1,000,006 boxes compare each on
/// every 6th judged frame; the shipped scenes up to 100,006 boxes on every judged frame.
constexpr std::size_t kSubquadraticBoxesPerJudgedFrame = 200000;

/// The fewest flat pairs whose midphase-completeness answers (the exhaustive vertex test and
/// each level list: microseconds a pair) go to the validators' threads.
constexpr std::size_t kParallelMidphasePairsFrom = 64;

/// The fewest validator threads per due broadphase of octocd's own (octree, octree-strict,
/// spatial-hash: their loops on the worker team) for candidate-sets to run those one after
/// another on every thread rather than side by side. Side by side on this project's 2-core
/// VM: boxes-uniform-100k's 5 judged frames 0.39 s against 0.50 one after another; one after
/// another on the H200 host's 16 threads: boxes-uniform-1m's 50 judged frames 9.0 -> 7.6 s.
constexpr std::size_t kThreadsPerTeamBroadphase = 4;

/// The judged frames between two comparisons of a broadphase of cost `cost` on `n` boxes:
/// ceil(n / kSubquadraticBoxesPerJudgedFrame) for a subquadratic one, the stride above for a
/// quadratic one (each at least 1).
std::uint64_t compare_stride(BroadPhaseCost cost, std::size_t n) {
  if (cost != BroadPhaseCost::quadratic)
    return std::max<std::uint64_t>(1, (n + kSubquadraticBoxesPerJudgedFrame - 1) / kSubquadraticBoxesPerJudgedFrame);
  return std::max<std::uint64_t>(
      1, static_cast<std::uint64_t>(std::ceil(quadratic_tests(n) / kQuadraticTestsPerJudgedFrame)));
}

/// The pair sets of the broadphases `bps[order[j]]` for j < `count` on the same boxes, each
/// into `outs[order[j]]`, on up to `threads` threads (each broadphase instance is used by
/// one thread at a time; the sets do not depend on the thread count). With `stop`, the
/// workers run detached and the caller polls stop() every 10 ms, throwing
/// ValidationStopped (a worker finishes the broadphase it holds, then leaves).
void find_pairs_all_stoppable(const std::vector<std::shared_ptr<BroadPhase>>& bps, const std::vector<std::size_t>& order,
                              std::size_t count, const std::vector<Aabb>& boxes, std::vector<std::vector<Pair>>& outs,
                              unsigned threads, const std::function<bool()>& stop) {
  if (count == 0) return;
  if (threads <= 1 || count == 1) {
    for (std::size_t j = 0; j < count; ++j) find_pairs_stoppable(bps[order[j]], boxes, outs[order[j]], stop);
    return;
  }
  if (stop && stop()) throw ValidationStopped();
  struct Job {
    std::vector<std::shared_ptr<BroadPhase>> bps;
    std::vector<Aabb> boxes;
    std::vector<std::vector<Pair>> pairs;
    std::atomic<std::size_t> next{0};
    std::atomic<bool> cancel{false};
    std::exception_ptr error;
    std::mutex m;
    std::condition_variable cv;
    unsigned running = 0;
  };
  auto job = std::make_shared<Job>();
  for (std::size_t j = 0; j < count; ++j) {
    job->bps.push_back(bps[order[j]]);
    job->pairs.emplace_back().swap(outs[order[j]]);  // keep their capacity
  }
  job->boxes = boxes;
  const unsigned workers = static_cast<unsigned>(std::min<std::size_t>(threads, count));
  job->running = workers;
  for (unsigned w = 0; w < workers; ++w)
    std::thread([job] {
      for (;;) {
        const std::size_t j = job->next.fetch_add(1);
        if (j >= job->bps.size() || job->cancel.load()) break;
        try {
          BroadPhaseStats st;
          job->bps[j]->find_pairs(job->boxes, job->pairs[j], st);
        } catch (...) {
          const std::lock_guard<std::mutex> lock(job->m);
          if (!job->error) job->error = std::current_exception();
          job->cancel.store(true);
          break;
        }
      }
      const std::lock_guard<std::mutex> lock(job->m);
      --job->running;
      job->cv.notify_all();
    }).detach();
  std::unique_lock<std::mutex> lock(job->m);
  while (!job->cv.wait_for(lock, std::chrono::milliseconds(10), [&] { return job->running == 0; }))
    if (stop && stop()) {
      job->cancel.store(true);
      throw ValidationStopped();
    }
  if (job->error) std::rethrow_exception(job->error);
  for (std::size_t j = 0; j < count; ++j) outs[order[j]].swap(job->pairs[j]);
}


}  // namespace

namespace {

/// Contacts per block of rows 4-6 (FrameValidators::observe): a block merged in a few
/// instructions, one with a row's first failure judged again on the calling thread.
constexpr std::size_t kContactBlock = 256;

/// The fewest contacts whose rows 4-6 run on the validators' threads.
constexpr std::size_t kParallelContactsFrom = 1024;

/// A CheckTally's checks of one block judged off the calling thread: counted, never
/// described (CheckTally keeps the text of its first failure only).
struct DryCheck {
  std::uint64_t checks = 0, failures = 0;
  double worst = 0.0;
  template <class F>
  void check(bool ok, double figure, F&&) {
    ++checks;
    worst = std::max(worst, figure);
    if (!ok) ++failures;
  }
  /// Whether `t`, given these checks, would write its first failure's text.
  bool replays(const CheckTally& t) const { return failures > 0 && t.failures == 0; }
  /// These checks added to `t` (where none replays: counts and the largest figure).
  void add_to(CheckTally& t) const {
    t.checks += checks;
    t.failures += failures;
    t.worst = std::max(t.worst, worst);
  }
};

}  // namespace

struct FrameValidators::Impl {
  const Model* model = nullptr;
  Source source;
  ValidationOptions options;
  ContactParams params;
  // Shared: a helper thread may still own one after a stop (find_pairs_stoppable).
  // `flat` is the reference pair set: exact_pairs, equal to the flat broadphase's set.
  std::shared_ptr<BroadPhase> flat;
  std::vector<std::shared_ptr<BroadPhase>> broadphases;
  std::vector<MidphaseConfig> configs;
  ConfirmFn confirm;
  std::unique_ptr<PhysicsValidators> physics;
  std::vector<Pair> expected;
  /// The static bodies (w = 0, in index order; the model's, set once), their boxes and their
  /// pairs (static_flat).
  std::vector<std::uint32_t> statics;
  std::vector<Aabb> static_boxes;
  std::vector<Pair> static_pairs;
  ExactPairsSettings pair_threads;
  /// `expected` = `with_dynamic` (flat's pairs with a dynamic body, sorted) joined with
  /// flat's pairs among the static bodies; false (expected unset) when that search is over
  /// its limit (PairLimitError): the caller searches every box.
  bool static_flat(const std::vector<Aabb>& boxes, const std::vector<Pair>& with_dynamic) {
    static_boxes.clear();
    for (const std::uint32_t i : statics) static_boxes.push_back(boxes[i]);
   
    if (statics.size() > 1) {
      try {
        exact_pairs(static_boxes, static_pairs, pair_threads);
      } catch (const PairLimitError&) {
        return false;
      }
      // Indices in the static list -> body indices: increasing, so (a, b) order is kept.
      for (Pair& q : static_pairs) q = Pair{statics[q.a], statics[q.b]};
    }
    expected.clear();
    expected.reserve(with_dynamic.size() + static_pairs.size());
    std::merge(with_dynamic.begin(), with_dynamic.end(), static_pairs.begin(), static_pairs.end(),
               std::back_inserter(expected));
    return true;
  }
  // Per compared broadphase (index into `broadphases`): its cost class, its last pair set and
  // the judged frames it was compared on; `bp_order` lists them quadratic-cost first.
  std::vector<BroadPhaseCost> bp_cost;
  /// Per compared broadphase: octocd's own subquadratic one, whose loops run on the worker
  /// team (octree, octree-strict, spatial-hash).
  std::vector<char> bp_team;
  std::vector<std::vector<Pair>> bp_pairs;
  std::vector<std::uint64_t> bp_compared;
  std::vector<std::size_t> bp_order;

  /// Midphase completeness: each flat pair's answers this frame (the row's loop).
  std::vector<std::uint32_t> midphase_answers;
  CheckTally candidates, midphase, contraction, friction, momentum, centre;
  std::unique_ptr<AppliedStateJudge> applied;
  std::uint64_t candidate_frames = 0, midphase_pairs = 0, dynamic_pairs = 0;
  // Contacts of another engine whose per-contact terms could not be derived (a dynamic
  // body with several contacts in the frame, or no states given).
  std::uint64_t contacts_unjudged = 0;
  // Candidate-set differences of the engine's own pairs: missing pairs all touching only
  // (an overlap of exactly zero on some axis: the engine's overlap test is not inclusive).
  std::uint64_t missing_pairs = 0, missing_touching = 0;
  double pen_max = 0.0, share_above_max = 0.0;
  // Each model row's own time (s, RowClock).
  double t_candidates = 0, t_midphase = 0, t_contraction = 0, t_applied = 0;
};

FrameValidators::FrameValidators(const Engine& engine, const ValidationOptions& options,
                                 std::vector<std::unique_ptr<BroadPhase>> broadphases)
    : FrameValidators(engine.model(), options, std::move(broadphases),
                      Source{fmt::format("engine {} ({})", engine.name(), engine.broadphase_name()), true,
                             false, nullptr}) {}

FrameValidators::FrameValidators(const Model& model, const ValidationOptions& options,
                                 std::vector<std::unique_ptr<BroadPhase>> broadphases, Source source)
    : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.model = &model;
  s.source = std::move(source);
  s.options = options;
  const Scene& scene = model.scene;
  s.params = scene.response;
  // `flat`'s pair set without its n(n-1)/2 tests (octocd/exact_pairs.hpp).
  ExactPairsSettings pair_threads;
  pair_threads.threads = options.threads;
  pair_threads.max_pairs_per_body = limits::kMaxPairsPerBody;
  s.flat = make_exact_pairs_broadphase(pair_threads);
  s.pair_threads = pair_threads;
  for (std::uint32_t i = 0; i < model.initial.w.size(); ++i)
    if (!(model.initial.w[i] > 0.0f)) s.statics.push_back(i);
  for (auto& bp : broadphases) {
    const BroadPhaseInfo* info = find_broadphase_info(bp->name());
    s.bp_cost.push_back(info ? info->cost : BroadPhaseCost::subquadratic);
    s.bp_team.push_back(info && info->host == BroadPhaseHost::core && info->cost != BroadPhaseCost::quadratic);
    s.broadphases.push_back(std::move(bp));
  }
  s.bp_pairs.resize(s.broadphases.size());
  s.bp_compared.assign(s.broadphases.size(), 0);
  for (std::size_t b = 0; b < s.broadphases.size(); ++b)
    if (s.bp_cost[b] == BroadPhaseCost::quadratic) s.bp_order.push_back(b);
  for (std::size_t b = 0; b < s.broadphases.size(); ++b)
    if (s.bp_cost[b] != BroadPhaseCost::quadratic) s.bp_order.push_back(b);
  // The paper's configurations A, B, C and the scene's own (design.md section 5.2).
  for (const char* text : {"2", "1,2", "0,1,2"}) s.configs.push_back(MidphaseConfig::parse(text));
  if (!scene.midphase.aabb_only &&
      std::none_of(s.configs.begin(), s.configs.end(), [&](const MidphaseConfig& c) {
        return c.levels == scene.midphase.levels;
      }))
    s.configs.push_back(scene.midphase);
  s.confirm = [](const PlacedShape& a, const PlacedShape& b, float theta, const MidphaseConfig& c,
                 MidphaseStats& st) { return confirm_contact(a, b, theta, c, st); };
  const PhysicsBodies bodies = s.source.physics ? *s.source.physics : octocd_physics_bodies(model);
  s.physics = std::make_unique<PhysicsValidators>(model, bodies, options.tol, s.source.label);
  s.applied = std::make_unique<AppliedStateJudge>(model, options.tol);
  s.physics->set_stop(options.stop);
  s.physics->set_threads(options.threads);
  if (options.judge_device) s.physics->set_judge_device(options.judge_device());
  s.applied->set_stop(options.stop);
  s.applied->set_threads(options.threads);
}

FrameValidators::~FrameValidators() = default;

void FrameValidators::set_midphase(ConfirmFn fn) { impl_->confirm = std::move(fn); }

void FrameValidators::observe(const Engine& world, bool checked) {
  const FrameRecord& rec = world.record();
  if (!world.can_record() || rec.frame != world.frame())
    throw RuntimeError(fmt::format("validators: engine '{}' gave no FrameRecord for frame {} "
                                   "(recording off or unsupported)",
                                   world.name(), world.frame()));
  observe(rec, checked);
}

void FrameValidators::observe(const FrameRecord& rec, bool checked) try {
  Impl& s = *impl_;
  const Model& model = *s.model;
  const std::int64_t frame = rec.frame;
  const bool has_states = !rec.x_pre.empty();
  StopPoll poll(s.options.stop);
  poll.now();
  // The physics tier: any engine, every frame (its costly rows on checked frames).
  s.physics->observe(rec, checked);
  // The model tier: the paper's response, for engines that claim it.
  const bool judge_response = s.source.octocd_pipeline || s.source.spec6_response;
  const std::vector<Aabb>& boxes = rec.aabbs;
  const std::vector<float>& w = model.initial.w;
  const ContactParams& p = s.params;
  const Tolerances& tol = s.options.tol;
  // The position the engine's collision detection used (after integration, design.md section 4.1).
  // octocd's engines: the same float32 integrate() they run (math.hpp), bit for bit; the
  // world AABB minus the local box would be off by an ulp, enough to flip a vertex test
  // sitting exactly at theta. Records without states: from the AABB.
  auto pre_position = [&](std::uint32_t i) {
    if (s.source.octocd_pipeline && has_states) {
      Vec3 x = rec.x_pre[i], v = rec.v_pre[i];
      integrate(x, v, w[i], model.scene.gravity, Vec3{}, model.scene.dt);
      return x;
    }
    return boxes[i].min - model.local_box(i).min;
  };
  auto placed = [&](std::uint32_t i) {
    const Shape& shape = model.shapes[model.bodies[i].shape];
    return PlacedShape{shape.octree.get(), pre_position(i), boxes[i]};
  };

  // Penetration statistics of the frame's contacts (AABB d_p, Eq. 10).
  if (!rec.contacts.empty()) {
    std::size_t above = 0;
    for (const ContactRecord& c : rec.contacts) {
      s.pen_max = std::max(s.pen_max, static_cast<double>(c.depth));
      if (c.depth > p.slop) ++above;
    }
    s.share_above_max = std::max(s.share_above_max,
                                 static_cast<double>(above) / static_cast<double>(rec.contacts.size()));
  }

  // Contacts per body in this frame (first pass): which contacts of another engine have
  // terms that the states give (every dynamic body of the pair has this contact only).
  std::vector<std::uint32_t> contacts_of;
  if (!rec.has_contact_terms) {
    contacts_of.assign(boxes.size(), 0);
    for (const ContactRecord& c : rec.contacts) {
      ++contacts_of[c.pair.a];
      ++contacts_of[c.pair.b];
    }
  }

  // 9. Applied state (design.md section 7.9): the engine's post-step state against the independent
  // re-derivation, every frame; momentum and centre on isolated dynamic groups. Only for an
  // engine that claims the paper's response: for any other both rows are n/a (results()),
  // so nothing of the re-derivation is read.
  if (has_states && judge_response) {
    const RowClock clock(s.t_applied);
    s.applied->observe(rec, judge_response);
  }

  if (checked && s.source.octocd_pipeline) {
    // 1. Candidate sets: octocd's (and the reference) broadphases equal `flat` as sets
    // (design.md section 7.1). Another engine's pairs are judged by the physics tier's broadphase
    // completeness (extras allowed), never against octocd's exact AABB rule.
    std::optional<RowClock> clock(std::in_place, s.t_candidates);
    // `flat`'s set: broadphase-completeness' pairs with a dynamic body, computed on this
    // frame's AABBs, joined with the static-static pairs (exact_pairs over the static bodies'
    // boxes); else one search of every box.
    const std::vector<Pair>* dynamic_pairs = s.physics->flat_pairs();
    if (!dynamic_pairs || !s.static_flat(boxes, *dynamic_pairs))
      find_pairs_stoppable(s.flat, boxes, s.expected, s.options.stop);
    ++s.candidate_frames;
    auto compare = [&](const std::vector<Pair>& got, const std::string& who, bool own) {
      const bool same = got == s.expected;
      std::string what;
      if (!same) {
        std::vector<Pair> missing, extra;
        std::set_difference(s.expected.begin(), s.expected.end(), got.begin(), got.end(),
                            std::back_inserter(missing));
        std::set_difference(got.begin(), got.end(), s.expected.begin(), s.expected.end(),
                            std::back_inserter(extra));
        const bool miss = !missing.empty();
        const Pair q = miss ? missing.front() : (extra.empty() ? Pair{} : extra.front());
        what = fmt::format("frame {}: {} {} pair ({}, {}) ({} missing, {} extra)", frame, who,
                           miss ? "misses" : "adds", q.a, q.b, missing.size(), extra.size());
        if (own) {
          // A pair whose boxes only touch (zero overlap on an axis) is a pair under the
          // inclusive rule of Eq. 6; an engine with a strict test misses exactly those.
          for (const Pair& m : missing) {
            ++s.missing_pairs;
            for (int k = 0; k < 3; ++k)
              if (overlap_along(boxes[m.a], boxes[m.b], k) == 0.0) {
                ++s.missing_touching;
                break;
              }
          }
        }
      }
      s.candidates.check(same, same ? 0.0 : 1.0, what);
    };
    // The pairs the engine itself used this frame (design.md section 7.9), then fresh instances.
    if (rec.has_pairs) compare(rec.pairs, s.source.label, true);
    // Every compared broadphase due this frame side by side on the validators' threads (the
    // slowest first); with at least kThreadsPerTeamBroadphase threads for each of octocd's
    // own due (their loops run on the worker team, which serves one caller's loop at a
    // time), those one after another on all the threads instead. Then compared in their
    // listed order.
    const std::uint64_t judged_frame = s.candidate_frames - 1;
    std::vector<std::size_t> due, beside, one_by_one;
    for (std::size_t b : s.bp_order)
      if (comparable(s.bp_cost[b], boxes.size()) && judged_frame % compare_stride(s.bp_cost[b], boxes.size()) == 0) {
        due.push_back(b);
        (s.bp_team[b] ? one_by_one : beside).push_back(b);
      }
    if (loop_threads(s.options.threads, boxes.size()) < kThreadsPerTeamBroadphase * one_by_one.size()) {
      beside = due;
      one_by_one.clear();
    }
    find_pairs_all_stoppable(s.broadphases, beside, beside.size(), boxes, s.bp_pairs,
                             loop_threads(s.options.threads, beside.size(), 2), s.options.stop);
    for (std::size_t b : one_by_one)
      find_pairs_stoppable(s.broadphases[b], boxes, s.bp_pairs[b], s.options.stop, s.options.threads);
    std::sort(due.begin(), due.end());
    for (std::size_t b : due) {
      ++s.bp_compared[b];
      compare(s.bp_pairs[b], s.broadphases[b]->name(), false);
    }

    // 2. Midphase completeness: every level list equals the exhaustive test (design.md section 7.2).
    {
      clock.emplace(s.t_midphase);
      // Each pair's answers on the validators' threads (bit 0 the exhaustive test's, bit 1
      // the engine's confirmed set's, bit 2 + k configuration k's; kSkipPair for a pair of
      // two static bodies), then tallied in pair order as one thread would.
      const std::vector<Pair>& pairs = s.expected;
      std::vector<std::uint32_t>& answers = s.midphase_answers;
      answers.resize(pairs.size());
      constexpr std::uint32_t kSkipPair = 0x80000000u;
      parallel_items_on(pairs.size(), loop_threads(s.options.threads, pairs.size(), kParallelMidphasePairsFrom),
                        s.options.stop, [&](std::size_t k, unsigned) {
        const Pair q = pairs[k];
        if (w[q.a] == 0.0f && w[q.b] == 0.0f) {
          answers[k] = kSkipPair;
          return;
        }
        const std::uint32_t sa = model.bodies[q.a].shape, sb = model.bodies[q.b].shape;
        const PlacedShape a = placed(q.a), b = placed(q.b);
        const float theta = model.theta(sa, sb);
        std::uint32_t bits = exhaustive_oracle(a, b, theta) ? 1u : 0u;
        // The engine's own verdict this frame (its confirmed set).
        if (std::binary_search(rec.confirmed.begin(), rec.confirmed.end(), q)) bits |= 2u;
        for (std::size_t c = 0; c < s.configs.size(); ++c) {
          MidphaseStats ms;
          if (s.confirm(a, b, theta, s.configs[c], ms)) bits |= 4u << c;
        }
        answers[k] = bits;
      });
      for (std::size_t k = 0; k < pairs.size(); ++k) {
        if (answers[k] == kSkipPair) continue;
        const Pair q = pairs[k];
        const bool truth = (answers[k] & 1u) != 0, engine_says = (answers[k] & 2u) != 0;
        ++s.midphase_pairs;
        s.midphase.check(engine_says == truth, engine_says == truth ? 0.0 : 1.0,
                         [&] { return fmt::format("frame {}: {} midphase [{}] says {} for pair ({}, {}), "
                                     "exhaustive says {}",
                                     frame, s.source.label, model.scene.midphase.to_string(), engine_says,
                                     q.a, q.b, truth); });
        for (std::size_t c = 0; c < s.configs.size(); ++c) {
          const bool got = (answers[k] & (4u << c)) != 0;
          s.midphase.check(got == truth, got == truth ? 0.0 : 1.0,
                           [&] { return fmt::format("frame {}: midphase {} says {} for pair ({}, {}), "
                                       "exhaustive says {}",
                                       frame, s.configs[c].to_string(), got, q.a, q.b, truth); });
        }
      }
    }
  }

  // 4-6 on the model's per-contact terms (the paper's response only). Each contact is
  // judged on its own: in blocks of kContactBlock on the validators' threads, each into its
  // own counts (DryCheck), merged in block order; a block with a failure where its row has
  // none yet is judged again on this thread, so every tally is the serial loop's, its
  // first failure's text included. The pass's time is row 4's (rows 5 and 6 share it).
  if (!judge_response) return;
  const RowClock clock(s.t_contraction);
  struct Counts {
    std::uint64_t unjudged = 0, dynamic_pairs = 0;
  };
  auto judge_contacts = [&](std::size_t first, std::size_t last, auto& contraction, auto& friction, auto& momentum,
                            auto& centre, Counts& counts) {
    for (std::size_t k = first; k < last; ++k) {
      const ContactRecord& given = rec.contacts[k];
      const float wa = w[given.pair.a], wb = w[given.pair.b];
      // 5. Friction cone, |J_t| <= mu_s J_n (section 3.3.2), on the reported impulses.
      const double cone = std::fabs(given.jt) - static_cast<double>(p.mu_static) * given.jn;
      const bool cone_ok = cone <= tol.friction_cone_rel * static_cast<double>(p.mu_static) * given.jn + 1e-9;
      // Another engine reports pair, normal, depth and impulses only. Where every dynamic
      // body of the pair has this one contact in the frame, its state change is this
      // contact's own: corrections from the world AABBs (the position after integration)
      // to x_post, velocity changes from the integrated v_pre (design.md section 4.1) to v_post.
      ContactRecord c = given;
      bool terms = rec.has_contact_terms;
      if (!terms && has_states &&
          (!(wa > 0.0f) || contacts_of[c.pair.a] == 1) && (!(wb > 0.0f) || contacts_of[c.pair.b] == 1)) {
        terms = true;
        const Vec3 n = c.normal;
        c.axis = std::fabs(n.x) >= std::fabs(n.y) && std::fabs(n.x) >= std::fabs(n.z) ? 0
                 : std::fabs(n.y) >= std::fabs(n.z)                                    ? 1
                                                                                       : 2;
        auto derive = [&](std::uint32_t i, Vec3& v, Vec3& dx, Vec3& dv) {
          v = rec.v_pre[i];
          if (w[i] > 0.0f) v = v + model.scene.dt * model.scene.gravity;
          dx = rec.x_post[i] - pre_position(i);
          dv = rec.v_post[i] - v;
        };
        derive(c.pair.a, c.v_a, c.dx_a, c.dv_a);
        derive(c.pair.b, c.v_b, c.dx_b, c.dv_b);
      }
      if (!terms) {
        ++counts.unjudged;
        friction.check(cone_ok, std::max(cone, 0.0),
                       [&] { return fmt::format("frame {}: pair ({}, {}) |J_t| {:.6g} vs mu_s J_n {:.6g}", frame, c.pair.a,
                                   c.pair.b, std::fabs(c.jt), p.mu_static * c.jn); });
        continue;
      }
      // 4. Non-penetration contraction (Eq. 14, section 3.3.3), this contact's own
      // correction only: d' - delta <= (1 - alpha beta)(d - delta) and no overshoot past
      // the slop (the sequence is monotone).
      {
        const double d = overlap_along(boxes[c.pair.a], boxes[c.pair.b], c.axis);
        const double d1 = overlap_along(shifted(boxes[c.pair.a], c.dx_a),
                                        shifted(boxes[c.pair.b], c.dx_b), c.axis);
        const double slop = p.slop;
        const double rate = 1.0 - static_cast<double>(p.alpha) * p.beta;
        double excess = 0.0;
        bool ok = true;
        if (wa + wb > 0.0f) {
          if (d > slop) {
            excess = std::max(d1 - slop - rate * (d - slop), (slop - d1));
            ok = d1 - slop <= rate * (d - slop) + tol.contraction_m && d1 - slop >= -tol.contraction_m;
          } else {
            excess = std::fabs(d1 - d);
            ok = excess <= tol.contraction_m;
          }
        }
        contraction.check(ok, std::max(excess, 0.0),
                          [&] { return fmt::format("frame {}: pair ({}, {}) depth {:.6g} -> {:.6g} m (slop {}, "
                                      "alpha beta {})",
                                      frame, c.pair.a, c.pair.b, d, d1, p.slop, p.alpha * p.beta); });
      }
      // 5. Friction: no rise of the relative tangential speed, |J_t| <= mu_s J_n (3.3.2).
      {
        const Vec3 before = tangential(c.v_a - c.v_b, c.normal);
        const Vec3 after = tangential((c.v_a + c.dv_a) - (c.v_b + c.dv_b), c.normal);
        const double rise = static_cast<double>(length(after)) - length(before);
        const bool ok = rise <= tol.friction_speed && cone_ok;
        friction.check(ok, std::max(rise, cone),
                       [&] { return fmt::format("frame {}: pair ({}, {}) |v_t| {:.6g} -> {:.6g} m/s, |J_t| {:.6g} "
                                   "vs mu_s J_n {:.6g}",
                                   frame, c.pair.a, c.pair.b, length(before), length(after),
                                   std::fabs(c.jt), p.mu_static * c.jn); });
      }
      // 6. Conservation per dynamic-dynamic contact: momentum and mass-weighted centre.
      if (wa > 0.0f && wb > 0.0f) {
        ++counts.dynamic_pairs;
        const double ma = 1.0 / wa, mb = 1.0 / wb;
        // Terms derived from another engine's states carry the float32 rounding of the
        // values they are differences of (positions through the AABBs, velocities): a few
        // roundings of those magnitudes, as for the applied state.
        auto inf = [](Vec3 u) { return std::max({std::fabs(u.x), std::fabs(u.y), std::fabs(u.z)}); };
        const double slack_x =
            rec.has_contact_terms
                ? 0.0
                : tol.applied_state_ulps * dmath::kEps32 * (ma + mb) *
                      std::max({inf(boxes[c.pair.a].min), inf(boxes[c.pair.a].max), inf(boxes[c.pair.b].min),
                                inf(boxes[c.pair.b].max)});
        const double slack_v =
            rec.has_contact_terms
                ? 0.0
                : tol.applied_state_ulps * dmath::kEps32 * (ma + mb) *
                      std::max({inf(c.v_a), inf(c.v_b), inf(c.v_a + c.dv_a), inf(c.v_b + c.dv_b)});
        auto check_pair = [&](auto& t, Vec3 da, Vec3 db, double rel, double slack, const char* what) {
          const double sx = ma * da.x + mb * db.x, sy = ma * da.y + mb * db.y,
                       sz = ma * da.z + mb * db.z;
          const double scale = ma * length(da) + mb * length(db);
          const double residual = norm(sx, sy, sz);
          const double share = scale > 0 ? residual / scale : 0.0;
          const double bound = rel * scale + slack + 1e-9;
          t.check(residual <= bound, residual / bound,
                  [&] { return fmt::format("frame {}: pair ({}, {}) {} changes by {:.3g} ({:.3g} of the exchange)",
                              frame, c.pair.a, c.pair.b, what, residual, share); });
        };
        check_pair(momentum, c.dv_a, c.dv_b, tol.momentum_rel, slack_v, "momentum");
        check_pair(centre, c.dx_a, c.dx_b, tol.centre_rel, slack_x, "mass-weighted centre");
      }
    }
  };
  const std::size_t n_contacts = rec.contacts.size();
  const std::size_t blocks = (n_contacts + kContactBlock - 1) / kContactBlock;
  auto live = [&](std::size_t b) {
    poll();
    Counts counts;
    judge_contacts(b * kContactBlock, std::min(n_contacts, (b + 1) * kContactBlock), s.contraction, s.friction,
                   s.momentum, s.centre, counts);
    s.contacts_unjudged += counts.unjudged;
    s.dynamic_pairs += counts.dynamic_pairs;
  };
  const unsigned threads = loop_threads(s.options.threads, n_contacts, kParallelContactsFrom);
  if (threads <= 1 || blocks < 2) {
    for (std::size_t b = 0; b < blocks; ++b) live(b);
  } else {
    struct Block {
      DryCheck contraction, friction, momentum, centre;
      Counts counts;
    };
    std::vector<Block> dry(blocks);
    parallel_items_on(blocks, threads, s.options.stop, [&](std::size_t b, unsigned) {
      Block& d = dry[b];
      judge_contacts(b * kContactBlock, std::min(n_contacts, (b + 1) * kContactBlock), d.contraction, d.friction,
                     d.momentum, d.centre, d.counts);
    });
    for (std::size_t b = 0; b < blocks; ++b) {
      const Block& d = dry[b];
      if (d.contraction.replays(s.contraction) || d.friction.replays(s.friction) || d.momentum.replays(s.momentum) ||
          d.centre.replays(s.centre)) {
        live(b);
        continue;
      }
      d.contraction.add_to(s.contraction);
      d.friction.add_to(s.friction);
      d.momentum.add_to(s.momentum);
      d.centre.add_to(s.centre);
      s.contacts_unjudged += d.counts.unjudged;
      s.dynamic_pairs += d.counts.dynamic_pairs;
    }
  }
} catch (const PairLimitError& e) {
  throw PairLimitError(fmt::format("frame {}: {}", rec.frame, e.what()), e);
}

PhysicsValidators& FrameValidators::physics() { return *impl_->physics; }

std::vector<ValidationResult> FrameValidators::results() const {
  const Impl& s = *impl_;
  // The physics tier first: it judges any engine.
  std::vector<ValidationResult> out = s.physics->results();
  const bool judge_response = s.source.octocd_pipeline || s.source.spec6_response;
  // Each model row's own time (RowClock), set on the rows of the tier when they are done.
  // Rows 4-6 are judged in one pass, timed as non-penetration-eq14's (observe).
  auto timed = [&](std::vector<ValidationResult>& rows) {
    const std::pair<RowId, double> seconds[] = {{RowId::CandidateSets, s.t_candidates},
                                                {RowId::MidphaseCompleteness, s.t_midphase},
                                                {RowId::NonPenetrationEq14, s.t_contraction},
                                                {RowId::AppliedState, s.t_applied}};
    for (ValidationResult& r : rows)
      for (const auto& [id, t] : seconds)
        if (r.tier == Tier::Model && r.name == row_info(id).name) r.seconds = t;
    return rows;
  };
  // Model-tier rows for another engine: n/a with the reason, never a FAIL.
  auto not_claimed = [&](RowId id, const char* figure, const char* why) {
    out.push_back(not_applicable(id, figure, why));
  };
  const char* no_spec6 = "another engine that does not claim design.md section 6 (response_model \"spec6\"): the paper's "
                         "response model is not judged; the physics tier judges its physics";
  auto tally = [](RowId id, const char* figure, const CheckTally& t, const std::string& ok_note) {
    ValidationResult r;
    r.tier = row_info(id).tier;
    r.name = row_info(id).name;
    r.figure = figure;
    r.measured = static_cast<double>(t.failures);
    r.bound = 0;
    r.pass = t.failures == 0;
    r.applicable = t.checks > 0;
    r.detail = t.failures ? t.first : fmt::format("{} checks; {}", t.checks, ok_note);
    return r;
  };
  if (s.source.octocd_pipeline) {
    std::string names = "flat's pair set (exact-grid) vs";
    const std::size_t n = s.model->bodies.size();
    for (std::size_t b = 0; b < s.broadphases.size(); ++b) {
      names += " " + s.broadphases[b]->name();
      if (!comparable(s.bp_cost[b], n))
        names += fmt::format(" (not compared: a quadratic broadphase's one call would be {:.2g} AABB tests on {} "
                             "boxes, above {:.0e})",
                             quadratic_tests(n), n, kQuadraticTestsPerCall);
      else if (const std::uint64_t stride = compare_stride(s.bp_cost[b], n);
               s.bp_compared[b] < (s.candidate_frames + stride - 1) / stride)
        // Fewer comparisons than its judged frames call for: the run stopped inside one.
        names += fmt::format(" (on {} of the {} frames: the run stopped before its comparison on the last)",
                             s.bp_compared[b], s.candidate_frames);
      else if (s.bp_compared[b] < s.candidate_frames && s.bp_cost[b] == BroadPhaseCost::quadratic)
        names += fmt::format(" (on {} of the {} frames: a quadratic broadphase is compared once in {} judged frames, "
                             "at most {:.0e} AABB tests a frame)",
                             s.bp_compared[b], s.candidate_frames, stride, kQuadraticTestsPerJudgedFrame);
      else if (s.bp_compared[b] < s.candidate_frames)
        names += fmt::format(" (on {} of the {} frames: above {} boxes a broadphase is compared once in {} judged "
                             "frames)",
                             s.bp_compared[b], s.candidate_frames, kSubquadraticBoxesPerJudgedFrame, stride);
    }
    out.push_back(tally(RowId::CandidateSets, "frames x broadphases differing from flat", s.candidates,
                        fmt::format("{} frames, the engine's own pairs and {}", s.candidate_frames, names)));
    if (s.missing_pairs > 0 && s.missing_touching == s.missing_pairs)
      out.back().detail += fmt::format("; all {} missing pairs only touch (zero overlap on an axis): overlap is "
                                       "inclusive (Eq. 6), min_A <= max_B and max_A >= min_B",
                                       s.missing_pairs);
    std::string cfgs;
    for (const auto& c : s.configs) cfgs += (cfgs.empty() ? "" : " ") + std::string("[") + c.to_string() + "]";
    out.push_back(tally(RowId::MidphaseCompleteness, "pair x level lists differing from exhaustive",
                        s.midphase, fmt::format("{} pairs, lists {}", s.midphase_pairs, cfgs)));
  } else {
    not_claimed(RowId::CandidateSets, "frames x broadphases differing from flat",
                "another engine: octocd's exact AABB rule (Eq. 6) is not required of it; its pairs are judged by "
                "broadphase-completeness (physics)");
    not_claimed(RowId::MidphaseCompleteness, "pair x level lists differing from exhaustive",
                "another engine: its contacts are not octocd's vertex-proximity test (design.md section 5.3)");
  }
  if (!judge_response) {
    not_claimed(RowId::NonPenetrationEq14, "contacts violating Eq. 14 contraction", no_spec6);
    not_claimed(RowId::FrictionMonotonicity, "contacts raising |v_t| or leaving the cone (Eq. 21-22)", no_spec6);
    not_claimed(RowId::ImpulseConservation, "contacts and isolated groups breaking momentum or centre", no_spec6);
    not_claimed(RowId::AppliedState, "bodies off the design.md section 6 re-derivation", no_spec6);
    return timed(out);
  }
  out.push_back(tally(RowId::NonPenetrationEq14, "contacts violating Eq. 14 contraction", s.contraction,
                      fmt::format("worst excess {:.3g} m; AABB penetration max {:.4g} m, share above "
                                  "slop up to {:.2f}",
                                  s.contraction.worst, s.pen_max, s.share_above_max)));
  out.back().tolerances = "contraction_m";
  out.push_back(tally(RowId::FrictionMonotonicity, "contacts raising |v_t| or leaving the cone (Eq. 21-22)",
                      s.friction, fmt::format("worst excess {:.3g}", s.friction.worst)));
  if (s.contacts_unjudged > 0) {
    // Another engine's contacts on a dynamic body with several contacts: only the cone.
    const std::string note = fmt::format("; {} contacts judged on the cone only (a dynamic body with several "
                                         "contacts, or no states)",
                                         s.contacts_unjudged);
    if (out.back().pass) out.back().detail += note;
    if (out[out.size() - 2].pass) out[out.size() - 2].detail += fmt::format(
        "; {} contacts not judged (a dynamic body with several contacts, or no states)", s.contacts_unjudged);
  }
  out.back().tolerances = "friction_speed,friction_cone_rel";
  {
    ValidationResult r = tally(RowId::ImpulseConservation, "contacts and isolated groups breaking momentum or centre",
                               CheckTally{}, "");
    // Worst figures are residual / bound over the items judged, so a pass shows <= 1.
    const AppliedStateJudge::Groups g = s.applied->groups();
    const std::uint64_t failures = s.momentum.failures + s.centre.failures + g.failures;
    r.measured = static_cast<double>(failures);
    r.pass = failures == 0;
    r.applicable = s.dynamic_pairs > 0 || g.groups > 0;
    r.detail = !g.first.empty()              ? g.first
               : !s.momentum.first.empty() ? s.momentum.first
               : !s.centre.first.empty()   ? s.centre.first
                                           : fmt::format("{} dynamic contacts judged (worst residual momentum {:.3g}, "
                                                         "centre {:.3g} of the bound); {} isolated groups on the "
                                                         "applied state judged ({} pairs for the centre; worst {:.3g} "
                                                         "of the bound)",
                                                         s.dynamic_pairs, s.momentum.worst, s.centre.worst, g.groups,
                                                         g.pairs, g.worst);
    r.tolerances = "momentum_rel,centre_rel,applied_conservation_rel";
    out.push_back(r);
  }
  {
    out.push_back(s.applied->result());
  }
  return timed(out);
}

}  // namespace octocd
