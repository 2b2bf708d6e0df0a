// Validators 7 (analytic scenes) and 8 (Bullet dynamics), the driver of `octocd validate`,
// the results table and /validation in traces.
#include <hdf5.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <future>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "octocd/bullet_world.hpp"
#include "octocd/error.hpp"
#include "octocd/setting_error.hpp"
#include "octocd/exact_pairs.hpp"
#include "octocd/pose.hpp"
#include "octocd/text.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/validation.hpp"
#include "octocd/validation_rows.hpp"

namespace octocd {

namespace {

/// Mass-weighted centre of the dynamic bodies.
Vec3 centre_of_mass(const BodyState& s) {
  double m = 0, x = 0, y = 0, z = 0;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s.w[i] == 0.0f) continue;
    const double mi = 1.0 / s.w[i];
    m += mi;
    x += mi * s.x[i].x;
    y += mi * s.x[i].y;
    z += mi * s.x[i].z;
  }
  if (m == 0) return {};
  return {static_cast<float>(x / m), static_cast<float>(y / m), static_cast<float>(z / m)};
}

/// Mean displacement of the dynamic bodies from positions `before` to state `now`, divided
/// by `seconds` (m/s); 0 without any. How fast the bodies move, whatever velocity the
/// state carries (octocd's resting bodies keep a downward velocity that the position
/// correction cancels every step: bunny-stack-50 rests with a mean |v| of 0.2 m/s).
double displacement_speed(const std::vector<Vec3>& before, const BodyState& now, double seconds) {
  double sum = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < now.size() && i < before.size(); ++i) {
    if (now.w[i] == 0.0f) continue;
    sum += length(now.x[i] - before[i]);
    ++n;
  }
  return n && seconds > 0 ? sum / static_cast<double>(n) / seconds : 0.0;
}

std::vector<std::size_t> dynamic_bodies(const Model& m) {
  std::vector<std::size_t> d;
  for (std::size_t i = 0; i < m.initial.size(); ++i)
    if (m.initial.w[i] > 0.0f) d.push_back(i);
  return d;
}

Aabb box_of(const Model& m, std::size_t i) { return translated(m.local_box(i), m.initial.x[i]); }

/// True when the x-z projections of two boxes overlap with positive area.
bool xz_overlap(const Aabb& a, const Aabb& b) {
  return a.min.x < b.max.x && a.max.x > b.min.x && a.min.z < b.max.z && a.max.z > b.min.z;
}

/// The highest top (max y) of the bodies in `candidates` that lie under `box` (x-z
/// overlap, top at or below box's bottom + slop); -inf when none.
float support_top(const Model& m, const Aabb& box, const std::vector<std::size_t>& candidates,
                  std::size_t self, float slop) {
  float top = -std::numeric_limits<float>::infinity();
  for (std::size_t j : candidates) {
    if (j == self) continue;
    const Aabb b = box_of(m, j);
    if (xz_overlap(box, b) && b.max.y <= box.min.y + slop) top = std::max(top, b.max.y);
  }
  return top;
}

/// Refuses, before the first step, a run whose checked frames would be refused: the
/// initial bodies' world AABBs through exact_pairs' limit (limits::kMaxPairsPerBody pairs a
/// body, octocd/exact_pairs.hpp). Without it the engine stepped 5,000 coincident boxes for
/// 28 s and 6.7 GB before the first checked frame was refused. Counts only (no pair kept
/// beyond the call): O(n log n) and the pairs of a legitimate scene.
void refuse_crowded_start(const Engine& engine) {
  const Model& model = engine.model();
  const BodyState& st = engine.state();
  std::vector<Aabb> boxes(st.size());
  for (std::size_t i = 0; i < st.size(); ++i)
    boxes[i] = posed_box_aabb(model.local_box(i), Pose{st.x[i], st.q.size() == st.size() ? st.q[i] : Quat{}});
  ExactPairsSettings limit;
  limit.max_pairs_per_body = limits::kMaxPairsPerBody;
  std::vector<Pair> pairs;
  try {
    exact_pairs(boxes, pairs, limit);
  } catch (const PairLimitError& e) {
    throw PairLimitError(fmt::format("scene '{}': frame 0 (the initial state, before any step): {}",
                                     printable(engine.scene().name), e.what()),
                         e);
  }
}

}  // namespace

const char* scene_kind_name(SceneKind kind) {
  switch (kind) {
    case SceneKind::FreeFall: return "free fall";
    case SceneKind::Bounce: return "bounce";
    case SceneKind::Slide: return "slide";
    case SceneKind::RestingStack: return "resting stack";
    case SceneKind::Pile: return "pile";
    case SceneKind::Other: break;
  }
  return "other";
}

SceneKind classify_scene(const Model& m) {
  const Scene& sc = m.scene;
  const std::vector<std::size_t> dyn = dynamic_bodies(m);
  std::vector<std::size_t> all(m.initial.size()), statics;
  for (std::size_t i = 0; i < all.size(); ++i) {
    all[i] = i;
    if (!(m.initial.w[i] > 0.0f)) statics.push_back(i);
  }
  const bool down = sc.gravity.x == 0.0f && sc.gravity.z == 0.0f && sc.gravity.y < 0.0f;
  if (dyn.empty() || !down) return SceneKind::Other;
  const float slop = sc.response.slop;
  if (dyn.size() == 1) {
    const std::size_t i = dyn.front();
    const Aabb box = box_of(m, i);
    const Vec3 v0 = m.initial.v[i];
    const float top = support_top(m, box, statics, i, slop);
    const bool sideways = v0.x != 0.0f || v0.z != 0.0f;
    if (top == -std::numeric_limits<float>::infinity()) {
      // Nothing under it: free fall, as long as nothing else can be met either.
      for (std::size_t j : statics)
        if (xz_overlap(box, box_of(m, j)) || sideways) return SceneKind::Other;
      return SceneKind::FreeFall;
    }
    const float gap = box.min.y - top;
    if (gap <= slop && v0.y == 0.0f && sideways) return SceneKind::Slide;
    if (gap > slop && !sideways) {
      const double impact = std::sqrt(static_cast<double>(v0.y) * v0.y + 2.0 * -sc.gravity.y * gap);
      if (impact > sc.response.restitution_threshold) return SceneKind::Bounce;
    }
    return SceneKind::Other;
  }
  for (std::size_t i : dyn)
    if (!(m.initial.v[i] == Vec3{})) return SceneKind::Other;
  // Several bodies at rest: a resting stack when each lies on something (within slop).
  bool resting = true, supported_somewhere = false;
  for (std::size_t i : dyn) {
    const Aabb box = box_of(m, i);
    const float top = support_top(m, box, all, i, slop);
    if (top == -std::numeric_limits<float>::infinity() || box.min.y - top > slop) resting = false;
  }
  for (std::size_t j : statics) {
    const Aabb b = box_of(m, j);
    for (std::size_t i : dyn)
      if (xz_overlap(box_of(m, i), b) && b.max.y <= box_of(m, i).min.y) supported_somewhere = true;
  }
  if (resting) return SceneKind::RestingStack;
  if (supported_somewhere) return SceneKind::Pile;
  return SceneKind::Other;
}

ValidationResult validate_analytic(Engine& engine, int frames, const Tolerances& tol,
                                   const std::function<bool()>& stop) {
  // Every engine step below is preceded by a poll (a long frame of a big scene is the
  // costly part here).
  auto step = [&]() -> const FrameMetrics& {
    if (stop && stop()) throw ValidationStopped();
    return engine.step();
  };
  const Model& model = engine.model();
  const Scene& sc = model.scene;
  const RowId row = RowId::Analytic;
  const SceneKind kind = classify_scene(model);
  ValidationResult r;
  r.tier = row_info(row).tier;
  r.name = row_info(row).name;
  const std::vector<std::size_t> dyn = dynamic_bodies(model);
  const int n_frames = std::max(frames, 1);
  if (kind == SceneKind::FreeFall) {
    // Eq. 2-3: v_n = v0 + n g dt, x_n = x0 + n dt v0 + g dt^2 n (n + 1) / 2.
    const std::size_t i = dyn.front();
    r.figure = "free fall: max |x - closed form| / (n (1 + |x|))";
    r.bound = tol.freefall_rel_per_step;
    r.tolerances = "freefall_rel_per_step";
    const Vec3 x0 = engine.state().x[i], v0 = engine.state().v[i];
    const double dt = sc.dt;
    for (int n = 1; n <= n_frames; ++n) {
      const FrameMetrics& fm = step();
      if (fm.contacts > 0) {
        r.measured = std::max(r.measured, 1.0);
        r.detail = fmt::format("frame {}: unexpected contact in free fall", n);
        break;
      }
      for (int k = 0; k < 3; ++k) {
        const double g = sc.gravity[k];
        const double x = x0[k] + n * dt * v0[k] + g * dt * dt * n * (n + 1) / 2.0;
        const double err = std::fabs(engine.state().x[i][k] - x) / (n * (1.0 + std::fabs(x)));
        if (err > r.measured) {
          r.measured = err;
          r.detail = fmt::format("worst at frame {}: x.{} {} vs {} m (body {})", n, "xyz"[k],
                                 engine.state().x[i][k], x, i);
        }
      }
    }
  } else if (kind == SceneKind::Bounce) {
    // Eq. 17, 19: above v_th the body leaves at e times the impact speed.
    const std::size_t i = dyn.front();
    r.figure = "bounce: |v_out - e v_in| / |v_in|";
    r.bound = tol.bounce_rel;
    r.tolerances = "bounce_rel";
    r.measured = 1.0;
    r.detail = fmt::format("never bounced in {} frames", n_frames);
    for (int n = 0; n < n_frames; ++n) {
      const float v_in = engine.state().v[i].y + sc.gravity.y * sc.dt;
      step();
      if (engine.state().v[i].y > 0.0f) {
        const double v_out = engine.state().v[i].y;
        r.measured = std::fabs(v_out + sc.response.restitution * v_in) / std::fabs(v_in);
        r.detail = fmt::format("frame {}: in {:.5f} m/s, out {:.5f} m/s, e {}", n + 1, v_in, v_out,
                               sc.response.restitution);
        break;
      }
    }
  } else if (kind == SceneKind::Slide) {
    // Eq. 20-22: a block sliding on the floor stops after v0^2 / (2 mu_k g).
    const std::size_t i = dyn.front();
    r.figure = "slide: |distance - v0^2/(2 mu_k g)| / that";
    r.bound = tol.slide_rel;
    r.tolerances = "slide_rel";
    const Vec3 x0 = engine.state().x[i];
    const double v0 = length(engine.state().v[i]);
    const double expected = v0 * v0 / (2.0 * sc.response.mu_kinetic * std::fabs(sc.gravity.y));
    const Vec3 dir = v0 > 0 ? (1.0f / static_cast<float>(v0)) * engine.state().v[i] : Vec3{};
    int n = 0;
    while (n < n_frames && dot(engine.state().v[i], dir) > 0.0f) {
      step();
      ++n;
    }
    const double travelled = dot(engine.state().x[i] - x0, dir);
    r.measured = std::fabs(travelled - expected) / expected;
    r.detail = fmt::format("stopped after {} frames at {:.5f} m, expected {:.5f} m", n, travelled, expected);
    if (dot(engine.state().v[i], dir) > 0.0f) {
      r.measured = std::max(r.measured, 1.0);
      r.detail = fmt::format("still sliding at {} m/s after {} frames", dot(engine.state().v[i], dir), n);
    }
  } else if (kind == SceneKind::RestingStack) {
    // Distance from rest: each body's rest height is its initial (touching) height lowered
    // by one slop per contact below it, since design.md section 6 leaves each contact's first delta of
    // penetration uncorrected. From frame 200 on (settling) every body stays within
    // stack_slops slops of it.
    r.figure = "resting stack: max |y - rest height| once settled (200 steps) / slop";
    r.bound = tol.stack_slops;
    r.tolerances = "stack_slops";
    constexpr int kSettle = 200;
    const float slop = sc.response.slop;
    std::vector<double> rest(model.initial.size(), 0.0);
    std::vector<std::size_t> all(model.initial.size());
    for (std::size_t j = 0; j < all.size(); ++j) all[j] = j;
    // Contacts below a body: 1 + those below whatever supports it (bottom-up order).
    std::vector<std::size_t> order = dyn;
    std::sort(order.begin(), order.end(),
              [&](std::size_t a, std::size_t b) { return model.initial.x[a].y < model.initial.x[b].y; });
    std::vector<int> below(model.initial.size(), 0);
    for (std::size_t i : order) {
      const Aabb box = box_of(model, i);
      int deepest = 0;
      for (std::size_t j : all) {
        if (j == i) continue;
        const Aabb b = box_of(model, j);
        if (xz_overlap(box, b) && std::fabs(b.max.y - box.min.y) <= slop)
          deepest = std::max(deepest, (model.initial.w[j] > 0.0f ? below[j] : 0) + 1);
      }
      below[i] = deepest;
      rest[i] = static_cast<double>(model.initial.x[i].y) - static_cast<double>(deepest) * slop;
    }
    // `frames` is honoured: a run shorter than the settling time is judged on its last
    // frame only (and says so).
    const int total = n_frames;
    const int from = std::min(kSettle, total);
    for (int n = 1; n <= total; ++n) {
      step();
      if (n < from) continue;
      for (std::size_t i : dyn) {
        const double d = std::fabs(engine.state().x[i].y - rest[i]) / slop;
        if (d > r.measured) {
          r.measured = d;
          r.detail = fmt::format("body {} at {:.6f} m, rest height {:.6f} m ({} contacts below) at frame {}",
                                 i, engine.state().x[i].y, rest[i], below[i], n);
        }
      }
    }
    if (r.detail.empty()) r.detail = fmt::format("{} frames", total);
    // Like a bounce or a slide that --frames cuts short, a stack that has not had its
    // settling time fails, saying why.
    r.detail += from == total ? fmt::format("; judged on frame {} only: settling takes {} steps, run "
                                            "--frames >= {} to judge the rest heights",
                                            total, kSettle, kSettle + 1)
                              : fmt::format("; frames {}..{} judged", from, total);
  } else {
    return not_applicable(row, "closed form of an analytic scene",
                          fmt::format("scene content is of kind '{}': not free fall, bounce, slide or a "
                                      "resting stack",
                                      scene_kind_name(kind)));
  }
  r.detail = fmt::format("{} (recognised: {})", r.detail, scene_kind_name(kind));
  r.pass = r.measured <= r.bound;
  return r;
}

ValidationResult validate_against_bullet(Engine& engine, int frames, const Tolerances& tol,
                                         const std::function<bool()>& stop) {
  const Model& model = engine.model();
  const RowId row = RowId::BulletDynamics;
  const SceneKind kind = classify_scene(model);
  const bool settle = kind == SceneKind::RestingStack || kind == SceneKind::Pile;
  const bool trajectory = kind == SceneKind::Bounce || kind == SceneKind::Slide;
  if (!settle && !trajectory)
    return not_applicable(row, "comparison with btDiscreteDynamicsWorld",
                          fmt::format("compared kinds: resting stack, pile, bounce, slide; this scene is of kind '{}'",
                                      scene_kind_name(kind)));
  std::shared_ptr<const Model> shared(&model, [](const Model*) {});  // outlives `bullet`
  // Box mode: octocd's translation-only response puts its contacts on the world AABBs, so
  // Bullet's boxes equal to the AABBs settle where octocd's bodies must (design.md section 7.8).
  BulletSettings boxes;
  boxes.shape = BulletShape::Box;
  BulletWorld bullet(shared, engine.state(), BulletOptions(), boxes);
  ValidationResult r;
  r.tier = row_info(row).tier;
  r.name = row_info(row).name;
  // Settling compares the state after `frames` steps, and how far the bodies moved over the
  // last tenth of them (1 to 100 frames); trajectories at every frame.
  const int n = std::max(frames, 1);
  const int window = std::clamp(n / 10, 1, 100);
  std::vector<Vec3> ours_before, theirs_before;
  double worst = 0.0;
  int worst_frame = 0;
  for (int f = 1; f <= n; ++f) {
    if (stop && stop()) throw ValidationStopped();
    if (f == n - window + 1) {
      ours_before = engine.state().x;
      theirs_before = bullet.state().x;
    }
    engine.step();
    bullet.step();
    if (trajectory) {
      const double d = length(centre_of_mass(engine.state()) - centre_of_mass(bullet.state()));
      if (d > worst) {
        worst = d;
        worst_frame = f;
      }
    }
  }
  if (trajectory) {
    r.figure = "max |centre of mass octocd - Bullet| (m)";
    r.measured = worst;
    r.bound = tol.bullet_trajectory_m;
    r.tolerances = "bullet_trajectory_m";
    r.detail = fmt::format("{} frames, worst at frame {} ({})", n, worst_frame, scene_kind_name(kind));
    r.judged = static_cast<std::uint64_t>(n);
  } else {
    double height = 0.0;
    int count = 0;
    for (std::size_t i = 0; i < engine.state().size(); ++i) {
      if (engine.state().w[i] == 0.0f) continue;
      const Aabb& b = model.local_box(i);
      height += b.max.y - b.min.y;
      ++count;
    }
    height /= std::max(count, 1);
    // At rest: the bodies' mean displacement over the window, per second, below a share of
    // sqrt(g h) (about the speed of a fall by one body height).
    const Vec3 g = model.scene.gravity;
    const double g_len = std::sqrt(double(g.x) * g.x + double(g.y) * g.y + double(g.z) * g.z);
    const double rest = tol.bullet_rest_speed_rel * std::sqrt(g_len * height);
    const double seconds = static_cast<double>(window) * model.scene.dt;
    const double ours_v = displacement_speed(ours_before, engine.state(), seconds);
    const double theirs_v = displacement_speed(theirs_before, bullet.state(), seconds);
    const char* figure = "settled centre-of-mass height difference / mean body height";
    if (theirs_v > rest)
      return not_applicable(
          row, figure,
          fmt::format("Bullet has not come to rest after {} frames ({}): its bodies moved {:.3g} m/s on average over "
                      "the last {} frames, at rest below {:.3g} m/s ({} x sqrt(g h), body height {:.3f} m); no "
                      "settled height to compare: validate with more --frames",
                      n, scene_kind_name(kind), theirs_v, window, rest, tol.bullet_rest_speed_rel, height));
    const double ours = centre_of_mass(engine.state()).y;
    const double theirs = centre_of_mass(bullet.state()).y;
    r.figure = figure;
    r.measured = std::fabs(ours - theirs) / height;
    r.bound = tol.bullet_height_rel;
    r.tolerances = "bullet_height_rel,bullet_rest_speed_rel";
    r.detail = fmt::format("after {} frames ({}): octocd {:.4f} m, Bullet {:.4f} m (body height {:.3f} m); moved "
                           "over the last {} frames: octocd {:.3g} m/s, Bullet {:.3g} m/s (at rest below {:.3g} m/s)",
                           n, scene_kind_name(kind), ours, theirs, height, window, ours_v, theirs_v, rest);
    r.judged = 1;
    r.pass = r.measured <= r.bound && ours_v <= rest;
    // Each failure is a cause of its own (a wrong height never hides a run that keeps moving).
    auto cause = [&](const RowCause& documented, double figure_value, std::string text) {
      ValidationCause c;
      c.name = documented.name;
      c.unit = documented.unit;
      c.count = 1;
      c.worst = figure_value;
      c.examples.push_back({n, "", figure_value, std::move(text)});
      r.causes.push_back(std::move(c));
    };
    if (!r.pass) {
      if (r.measured > r.bound)
        cause(row_info(row).causes[0], r.measured,  // height
              fmt::format("settled centre-of-mass heights differ by {:.3g} body heights (bound {:.3g}): octocd "
                          "{:.4f} m, Bullet {:.4f} m",
                          r.measured, r.bound, ours, theirs));
      if (ours_v > rest)
        cause(row_info(row).causes[1], ours_v,  // still-moving
              fmt::format("octocd's bodies still move ({:.3g} m/s on average over the last {} frames) where "
                          "Bullet's rest ({:.3g} m/s; at rest below {:.3g} m/s)",
                          ours_v, window, theirs_v, rest));
    }
    return r;
  }
  r.pass = r.measured <= r.bound;
  return r;
}

const std::vector<ToleranceEntry>& tolerance_table() {
  static const std::vector<ToleranceEntry> table = {
#define OCTOCD_TOLERANCE(name, value, unit, doc) {#name, &Tolerances::name, unit, doc, value},
#include "octocd/tolerances.def"
#undef OCTOCD_TOLERANCE
  };
  return table;
}

void set_tolerance(Tolerances& tol, const std::string& name, double value) {
  std::string names;
  for (const ToleranceEntry& e : tolerance_table()) {
    names += (names.empty() ? "" : ", ") + std::string(e.name);
    if (name != e.name) continue;
    if (!std::isfinite(value) || value < 0.0)
      throw SettingError("tolerance", name, fmt::format("{}", value), true,
                         fmt::format("a finite number >= 0 ({})", e.unit));
    tol.*(e.member) = value;
    return;
  }
  throw SettingError("tolerance", name, "", false, names);
}

std::vector<std::unique_ptr<BroadPhase>> compared_broadphases(const Scene& scene, bool with_references) {
  std::vector<std::unique_ptr<BroadPhase>> broadphases;
  for (const std::string& name : with_references ? all_broadphase_names() : broadphase_names()) {
    if (find_broadphase_info(name)->pairs == BroadPhasePairs::oracle) continue;  // what the others are compared with
    BroadPhaseConfig cfg = scene.broadphase;
    cfg.name = name;
    broadphases.push_back(make_any_broadphase(cfg, scene.domain));
  }
  return broadphases;
}

std::vector<ValidationResult> validate_engine(const EngineFactory& make, const ValidationOptions& options,
                                              std::int64_t* stopped_in) {
  if (stopped_in) *stopped_in = 0;
  std::unique_ptr<Engine> engine = make();
  if (!engine->can_record())
    throw InputError(fmt::format("validate: engine '{}' cannot record its frames (FrameRecord); "
                                 "allowed engines: cpu, cuda",
                                 engine->name()));
  engine->set_recording(true);
  // A run with a checked frame: its initial bodies within the pair limit, before any step.
  if (options.every <= options.frames) refuse_crowded_start(*engine);
  FrameValidators validators(*engine, options, compared_broadphases(engine->scene(), options.against_fcl));
  int done = 0;
  bool stopped = false, inside = false;
  // options.pipeline: frame f is judged (on a copy of its record) while the engine runs
  // frame f + 1; one frame in flight, judged in order, so the verdicts are the serial
  // run's. Otherwise (or threads 1): judged in turn on this thread.
  const bool pipelined = options.pipeline && options.threads != 1;
  std::future<void> judging;
  int judging_frame = 0;
  // The verdict a stop after frame `done` gives (the reruns n/a), for options.on_judged.
  auto stopped_rows = [&] {
    std::vector<ValidationResult> rows = validators.results();
    const std::string why = fmt::format("not run: stopped after frame {} of {}", done, options.frames);
    rows.push_back(not_applicable(RowId::Analytic, "closed form of an analytic scene", why));
    rows.push_back(not_applicable(RowId::BulletDynamics, "comparison with btDiscreteDynamicsWorld", why));
    return rows;
  };
  auto judged = [&] {
    if (options.on_judged) options.on_judged(stopped_rows(), done);
  };
  auto finish = [&] {  // waits for the frame in flight; rethrows its errors
    if (!judging.valid()) return;
    judging.get();
    done = judging_frame;
    judged();
  };
  try {
    for (int f = 1; f <= options.frames; ++f) {
      if (options.stop && options.stop()) {
        stopped = true;
        break;
      }
      engine->step();
      const bool checked = f % options.every == 0;
      if (!pipelined) {
        validators.observe(*engine, checked);  // polls options.stop inside
        if (options.on_step) options.on_step(*engine);
        done = f;
        judged();
        continue;
      }
      const FrameRecord& live = engine->record();
      if (!engine->can_record() || live.frame != engine->frame())
        throw RuntimeError(fmt::format("validators: engine '{}' gave no FrameRecord for frame {} "
                                       "(recording off or unsupported)",
                                       engine->name(), engine->frame()));
      auto rec = std::make_shared<const FrameRecord>(live);
      if (options.on_step) options.on_step(*engine);
      finish();  // frame f - 1 judged
      judging = std::async(std::launch::async, [&validators, rec, checked] { validators.observe(*rec, checked); });
      judging_frame = f;
    }
    finish();
  } catch (const ValidationStopped&) {
    stopped = inside = true;  // inside frame done + 1's checks: it is partly judged
  }
  if (stopped) {  // the validators that rerun the scene do not run
    if (stopped_in && inside) *stopped_in = done + 1;
    return stopped_rows();
  }
  std::vector<ValidationResult> results = validators.results();
  // Validators 7 and 8 rerun the scene on fresh engines (their time is their row's).
  auto rerun = [&](RowId row, const char* figure, auto judge) {
    const auto t0 = std::chrono::steady_clock::now();
    try {
      std::unique_ptr<Engine> fresh = make();
      results.push_back(judge(*fresh));
    } catch (const ValidationStopped&) {
      stopped = true;
      results.push_back(not_applicable(row, figure, "not run to its end: stopped by a signal"));
    }
    results.back().seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  rerun(RowId::Analytic, "closed form of an analytic scene",
        [&](Engine& e) { return validate_analytic(e, options.frames, options.tol, options.stop); });
  if (stopped) {
    results.push_back(not_applicable(RowId::BulletDynamics, "comparison with btDiscreteDynamicsWorld",
                                     "not run: stopped by a signal"));
    return results;
  }
  if (options.against_bullet) {
    rerun(RowId::BulletDynamics, "comparison with btDiscreteDynamicsWorld",
          [&](Engine& e) { return validate_against_bullet(e, options.frames, options.tol, options.stop); });
  } else {
    results.push_back(not_applicable(RowId::BulletDynamics, "comparison with btDiscreteDynamicsWorld",
                                     "Bullet not requested (--against)"));
  }
  return results;
}

std::vector<ValidationResult> validate_scene(const Scene& scene, const ValidationOptions& options) {
  const std::shared_ptr<const Model> model = build_model(scene);
  return validate_engine(
      [&]() -> std::unique_ptr<Engine> {
        return std::make_unique<World>(model, make_any_broadphase(scene.broadphase, scene.domain));
      },
      options);
}

const char* tier_name(Tier tier) { return tier == Tier::Physics ? "physics" : "model"; }

namespace {
constexpr Tier kTiers[] = {Tier::Physics, Tier::Model};
}  // namespace

std::optional<Tier> find_tier(const std::string& name) {
  for (const Tier t : kTiers)
    if (name == tier_name(t)) return t;
  return std::nullopt;
}

const std::vector<std::string>& tier_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> v;
    for (const Tier t : kTiers) v.emplace_back(tier_name(t));
    return v;
  }();
  return names;
}

void write_validation(const std::string& path, const std::vector<ValidationResult>& results) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  if (file < 0) throw RuntimeError(fmt::format("trace '{}': cannot open for writing /validation", path));
  bool ok = true;
  if (H5Lexists(file, "/validation", H5P_DEFAULT) > 0) ok = H5Ldelete(file, "/validation", H5P_DEFAULT) >= 0;
  const hid_t group = H5Gcreate2(file, "/validation", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  ok = ok && group >= 0;
  const hsize_t n = results.size();
  const hid_t space = H5Screate_simple(1, &n, nullptr);
  auto strings = [&](const char* dname, auto get) {
    std::vector<std::string> keep;
    std::vector<const char*> ptrs;
    for (const auto& r : results) keep.push_back(get(r));
    for (const auto& s : keep) ptrs.push_back(s.c_str());
    const hid_t type = H5Tcopy(H5T_C_S1);
    H5Tset_size(type, H5T_VARIABLE);
    H5Tset_cset(type, H5T_CSET_UTF8);
    const hid_t d = H5Dcreate2(group, dname, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    ok = ok && d >= 0 && H5Dwrite(d, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, ptrs.data()) >= 0;
    H5Dclose(d);
    H5Tclose(type);
  };
  auto numbers = [&](const char* dname, hid_t mem, hid_t file_type, const void* data) {
    const hid_t d = H5Dcreate2(group, dname, file_type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    ok = ok && d >= 0 && H5Dwrite(d, mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) >= 0;
    H5Dclose(d);
  };
  if (ok) {
    strings("tier", [](const ValidationResult& r) { return std::string(tier_name(r.tier)); });
    strings("name", [](const ValidationResult& r) { return r.name; });
    strings("figure", [](const ValidationResult& r) { return r.figure; });
    strings("detail", [](const ValidationResult& r) { return r.detail; });
    std::vector<double> measured, bound;
    std::vector<std::uint8_t> pass, applicable;
    for (const auto& r : results) {
      measured.push_back(r.measured);
      bound.push_back(r.bound);
      pass.push_back(r.pass ? 1 : 0);
      applicable.push_back(r.applicable ? 1 : 0);
    }
    numbers("measured", H5T_NATIVE_DOUBLE, H5T_IEEE_F64LE, measured.data());
    numbers("bound", H5T_NATIVE_DOUBLE, H5T_IEEE_F64LE, bound.data());
    numbers("pass", H5T_NATIVE_UINT8, H5T_STD_U8LE, pass.data());
    numbers("applicable", H5T_NATIVE_UINT8, H5T_STD_U8LE, applicable.data());
  }
  H5Sclose(space);
  if (group >= 0) H5Gclose(group);
  ok = H5Fclose(file) >= 0 && ok;
  if (!ok) throw RuntimeError(fmt::format("trace '{}': writing /validation failed", path));
}

}  // namespace octocd
