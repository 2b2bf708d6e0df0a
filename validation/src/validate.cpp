// Validators 7 (analytic scenes) and 8 (Bullet dynamics), the driver of `octocd validate`,
// the results table and /validation in traces.
#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "octocd/bullet_world.hpp"
#include "octocd/error.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/validation.hpp"

namespace octocd {

namespace {

/// Index of the first dynamic body (the analytic scenes have walls first, then one group).
std::size_t first_dynamic(const World& w) {
  for (std::size_t i = 0; i < w.state().size(); ++i)
    if (w.state().w[i] > 0.0f) return i;
  return 0;
}

ValidationResult not_applicable(const char* name, const char* figure, const std::string& why) {
  ValidationResult r;
  r.name = name;
  r.figure = figure;
  r.applicable = false;
  r.detail = why;
  return r;
}

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

}  // namespace

ValidationResult validate_analytic(World& world, const Tolerances& tol) {
  const Scene& sc = world.scene();
  const char* name = "analytic";
  const std::size_t i = first_dynamic(world);
  ValidationResult r;
  r.name = name;
  if (sc.name == "free-fall") {
    // Eq. 2-3: v_n = v0 + n g dt, x_n = x0 + n dt v0 + g dt^2 n (n + 1) / 2.
    r.figure = "free fall: max |x - closed form| / (n (1 + |x|))";
    r.bound = tol.freefall_rel_per_step;
    const Vec3 x0 = world.state().x[i], v0 = world.state().v[i];
    const double g = sc.gravity.y, dt = sc.dt;
    for (int n = 1; n <= sc.frames; ++n) {
      world.step();
      const double x = x0.y + n * dt * v0.y + g * dt * dt * n * (n + 1) / 2.0;
      const double err = std::fabs(world.state().x[i].y - x) / (n * (1.0 + std::fabs(x)));
      if (err > r.measured) {
        r.measured = err;
        r.detail = fmt::format("worst at frame {}: {} vs {} m", n, world.state().x[i].y, x);
      }
    }
  } else if (sc.name == "bounce") {
    // Eq. 17, 19: above v_th the body leaves at e times the impact speed.
    r.figure = "bounce: |v_out - e v_in| / |v_in|";
    r.bound = tol.bounce_rel;
    r.measured = 1.0;
    r.detail = "never bounced";
    for (int n = 0; n < sc.frames; ++n) {
      const float v_in = world.state().v[i].y + sc.gravity.y * sc.dt;
      world.step();
      if (world.state().v[i].y > 0.0f) {
        const double v_out = world.state().v[i].y;
        r.measured = std::fabs(v_out + sc.response.restitution * v_in) / std::fabs(v_in);
        r.detail = fmt::format("frame {}: in {:.5f} m/s, out {:.5f} m/s, e {}", n + 1, v_in, v_out,
                               sc.response.restitution);
        break;
      }
    }
  } else if (sc.name == "slide") {
    // Eq. 20-22: a block sliding on the floor stops after v0^2 / (2 mu_k g).
    r.figure = "slide: |distance - v0^2/(2 mu_k g)| / that";
    r.bound = tol.slide_rel;
    const Vec3 x0 = world.state().x[i];
    const double v0 = length(world.state().v[i]);
    const double expected = v0 * v0 / (2.0 * sc.response.mu_kinetic * std::fabs(sc.gravity.y));
    const Vec3 dir = v0 > 0 ? (1.0f / static_cast<float>(v0)) * world.state().v[i] : Vec3{};
    int n = 0;
    while (n < sc.frames && dot(world.state().v[i], dir) > 0.0f) {
      world.step();
      ++n;
    }
    const double travelled = dot(world.state().x[i] - x0, dir);
    r.measured = std::fabs(travelled - expected) / expected;
    r.detail = fmt::format("stopped after {} frames at {:.5f} m, expected {:.5f} m", n, travelled, expected);
    if (dot(world.state().v[i], dir) > 0.0f) {
      r.measured = std::max(r.measured, 1.0);
      r.detail = fmt::format("still sliding at {} m/s after {} frames", dot(world.state().v[i], dir), n);
    }
  } else if (sc.name == "box-stack") {
    // A resting stack stays within delta of rest once settled (see tests for the settling).
    r.figure = "box stack: max displacement after settling / slop";
    r.bound = tol.stack_slops;
    constexpr int kSettle = 200;
    BodyState rest;
    for (int n = 1; n <= std::max(sc.frames, kSettle + 1); ++n) {
      world.step();
      if (n == kSettle) rest = world.state();
      if (n <= kSettle) continue;
      for (std::size_t k = 0; k < rest.size(); ++k) {
        if (rest.w[k] == 0.0f) continue;
        const double d = length(world.state().x[k] - rest.x[k]) / sc.response.slop;
        if (d > r.measured) {
          r.measured = d;
          r.detail = fmt::format("body {} moved {:.3g} m by frame {}", k, d * sc.response.slop, n);
        }
      }
    }
  } else {
    return not_applicable(name, "closed form of an analytic scene",
                          "not an analytic scene (free-fall, bounce, slide, box-stack)");
  }
  r.pass = r.measured <= r.bound;
  return r;
}

ValidationResult validate_against_bullet(World& world, int frames, const Tolerances& tol) {
  const Scene& sc = world.scene();
  const char* name = "bullet-dynamics";
  const bool settle = sc.name == "box-stack" || sc.name == "bunny-stack-50";
  const bool trajectory = sc.name == "bounce" || sc.name == "slide";
  if (!settle && !trajectory)
    return not_applicable(name, "comparison with btDiscreteDynamicsWorld",
                          "compared scenes: box-stack, bunny-stack-50, bounce, slide");
  BulletWorld bullet(world);
  ValidationResult r;
  r.name = name;
  // Settling needs the whole scene; trajectories are compared over the same frames.
  const int n = std::max(frames, sc.frames);
  double worst = 0.0;
  int worst_frame = 0;
  for (int f = 1; f <= n; ++f) {
    world.step();
    bullet.step();
    if (trajectory) {
      const double d = length(centre_of_mass(world.state()) - centre_of_mass(bullet.state()));
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
    r.detail = fmt::format("{} frames, worst at frame {}", n, worst_frame);
  } else {
    double height = 0.0;
    int count = 0;
    for (std::size_t i = 0; i < world.state().size(); ++i) {
      if (world.state().w[i] == 0.0f) continue;
      const Aabb& b = world.shapes()[world.bodies()[i].shape].local;
      height += b.max.y - b.min.y;
      ++count;
    }
    height /= std::max(count, 1);
    const double ours = centre_of_mass(world.state()).y;
    const double theirs = centre_of_mass(bullet.state()).y;
    r.figure = "settled centre-of-mass height difference / mean body height";
    r.measured = std::fabs(ours - theirs) / height;
    r.bound = tol.bullet_height_rel;
    r.detail = fmt::format("after {} frames: octocd {:.4f} m, Bullet {:.4f} m (body height {:.3f} m)", n,
                           ours, theirs, height);
  }
  r.pass = r.measured <= r.bound;
  return r;
}

std::vector<ValidationResult> validate_scene(const Scene& scene, const ValidationOptions& options) {
  World world(scene, make_any_broadphase(scene.broadphase, scene.domain));
  std::vector<std::unique_ptr<BroadPhase>> broadphases;
  const std::vector<std::string> names =
      options.against_fcl ? all_broadphase_names() : broadphase_names();
  for (const std::string& name : names) {
    if (name == "flat") continue;
    BroadPhaseConfig cfg = scene.broadphase;
    cfg.name = name;
    broadphases.push_back(make_any_broadphase(cfg, scene.domain));
  }
  FrameValidators validators(world, options, std::move(broadphases));
  for (int f = 1; f <= options.frames; ++f) {
    world.step();
    validators.observe(world, f % options.every == 0);
    if (options.on_step) options.on_step(world);
  }
  std::vector<ValidationResult> results = validators.results();
  {
    World fresh(scene);
    results.push_back(validate_analytic(fresh, options.tol));
  }
  if (options.against_bullet) {
    World fresh(scene);
    results.push_back(validate_against_bullet(fresh, options.frames, options.tol));
  } else {
    results.push_back(not_applicable("bullet-dynamics", "comparison with btDiscreteDynamicsWorld",
                                     "Bullet not requested (--against)"));
  }
  return results;
}

std::string format_results(const std::vector<ValidationResult>& results) {
  std::string out = fmt::format("{:<22} {:>12} {:>10}  {:<5}  {}\n", "validator", "measured", "bound",
                                "", "figure / detail");
  for (const ValidationResult& r : results) {
    const char* verdict = !r.applicable ? "n/a" : (r.pass ? "pass" : "FAIL");
    out += fmt::format("{:<22} {:>12.6g} {:>10.4g}  {:<5}  {}\n", r.name, r.measured, r.bound, verdict,
                       r.figure);
    out += fmt::format("{:<22} {:>12} {:>10}  {:<5}  {}\n", "", "", "", "", r.detail);
  }
  return out;
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
