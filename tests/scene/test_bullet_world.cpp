// octocd::BulletWorld (design.md section 7 item 8): the analytic scenes run in Bullet's
// btDiscreteDynamicsWorld, against the same closed forms as octocd's own pipeline.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <string>

#include "octocd/bullet_world.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_bullet_world {

using namespace octocd;

namespace {

std::string scene_path(const std::string& name) {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return std::string(root ? root : ".") + "/datasets/scenes/" + name + ".json";
}

/// Index of the first dynamic body (the scenes here have one dynamic group).
std::size_t first_dynamic(const BodyState& s) {
  for (std::size_t i = 0; i < s.size(); ++i)
    if (s.w[i] > 0.0f) return i;
  ADD_FAILURE() << "no dynamic body";
  return 0;
}

}  // namespace

// Bullet integrates semi-implicit Euler (btRigidBody::integrateVelocities then
// btTransformUtil::integrateTransform with the new velocity), the same as design.md section 4.1, so
// the closed form is octocd's: v_n = v0 + n g dt, x_n = x0 + n dt v0 + g dt^2 n (n+1)/2.
// Tolerances: v within 1e-5 (1 + |v|) (float rounding of n additions); x within
// 2e-6 n (1 + |x|) (float32 state, error grows like n ulp(|x|)); and, the sharp check,
// every per-step increment x_n - x_{n-1} equals v_n dt within 2e-6 m (about 2 ulp at
// |x| = 10 m), whereas explicit Euler (x += v_{n-1} dt) would be off by |g| dt^2 =
// 9.8e-6 m per step.
TEST(BulletWorld, FreeFallMatchesSemiImplicitEuler) {
  const Scene scene = load_scene(scene_path("free-fall"));
  World world(scene);
  BulletWorld bw(world);
  const std::size_t i = first_dynamic(bw.state());
  const Vec3 x0 = bw.state().x[i], v0 = bw.state().v[i];
  EXPECT_EQ(x0.y, world.state().x[i].y);
  const double g = scene.gravity.y, dt = scene.dt;
  double worst = 0.0;
  for (int n = 1; n <= scene.frames; ++n) {
    const double x_prev = bw.state().x[i].y;
    const FrameMetrics& fm = bw.step();
    ASSERT_EQ(fm.frame, n);
    const double v = v0.y + n * g * dt;
    const double x = x0.y + n * dt * v0.y + g * dt * dt * n * (n + 1) / 2.0;
    const double xn = bw.state().x[i].y, vn = bw.state().v[i].y;
    worst = std::max(worst, std::fabs(xn - x));
    ASSERT_NEAR(vn, v, 1e-5 * (1 + std::fabs(v))) << "frame " << n;
    ASSERT_NEAR(xn, x, 2e-6 * n * (1 + std::fabs(x))) << "frame " << n;
    ASSERT_NEAR(xn - x_prev, vn * dt, 2e-6) << "frame " << n << ": not semi-implicit Euler";
    ASSERT_EQ(bw.state().x[i].x, x0.x);
    ASSERT_EQ(fm.contacts, 0u);
  }
  EXPECT_EQ(bw.frame(), scene.frames);
  // Energy bookkeeping: 0.5 m v^2 of the single body.
  const double vy = bw.state().v[i].y, m = 1.0 / bw.state().w[i];
  EXPECT_NEAR(bw.last_metrics().kinetic_energy, 0.5 * m * vy * vy, 1e-9);
  EXPECT_NEAR(bw.last_metrics().momentum[1], m * vy, 1e-9);
  RecordProperty("max_position_error_m", std::to_string(worst));
}

// The first rebound speed over the impact speed is the restitution e (product of the
// two bodies' sqrt(e), see bullet_world.hpp) within 0.1 absolute.
TEST(BulletWorld, BounceReturnsAtRestitution) {
  const Scene scene = load_scene(scene_path("bounce"));
  World world(scene);
  BulletWorld bw(world);
  const std::size_t i = first_dynamic(bw.state());
  bool bounced = false;
  double ratio = 0.0, v_impact = 0.0;
  for (int n = 0; n < scene.frames && !bounced; ++n) {
    const float v_prev = bw.state().v[i].y;
    bw.step();
    if (bw.state().v[i].y > 0.0f) {
      bounced = true;
      v_impact = v_prev + scene.gravity.y * scene.dt;  // after the velocity integration
      ratio = bw.state().v[i].y / -v_impact;
    }
  }
  ASSERT_TRUE(bounced) << "the body never bounced";
  EXPECT_GT(-v_impact, scene.response.restitution_threshold);
  std::printf("bounce: impact %.4f m/s, rebound ratio %.4f (e = %.3f)\n", -v_impact, ratio,
              scene.response.restitution);
  RecordProperty("rebound_ratio", std::to_string(ratio));
  EXPECT_NEAR(ratio, scene.response.restitution, 0.1);
}

// A block launched along the floor decelerates and stops; its stopping distance is
// compared with v0^2 / (2 mu_k g) (Bullet: one friction coefficient, combined as the
// product sqrt(mu_k)^2 = mu_k). Tolerance 10%.
TEST(BulletWorld, SlideStopsNearCoulombDistance) {
  const Scene scene = load_scene(scene_path("slide"));
  World world(scene);
  BulletWorld bw(world);
  const std::size_t i = first_dynamic(bw.state());
  const Vec3 x0 = bw.state().x[i];
  const double v0 = bw.state().v[i].x;
  ASSERT_GT(v0, 0.0);
  int n = 0;
  float v_prev = bw.state().v[i].x;
  constexpr float kStopped = 1e-3f;  // m/s
  while (n < scene.frames && bw.state().v[i].x > kStopped) {
    bw.step();
    ++n;
    ASSERT_LE(bw.state().v[i].x, v_prev + 1e-6f) << "frame " << n << ": sped up";
    v_prev = bw.state().v[i].x;
  }
  ASSERT_LE(bw.state().v[i].x, kStopped) << "still sliding after " << n << " frames";
  const double expected = v0 * v0 / (2.0 * scene.response.mu_kinetic * -scene.gravity.y);
  const double travelled = bw.state().x[i].x - x0.x;
  const double ratio = travelled / expected;
  std::printf("slide: stopped after %d frames, %.4f m; v0^2/(2 mu g) = %.4f m; ratio %.4f\n",
              n, travelled, expected, ratio);
  RecordProperty("stopping_distance_ratio", std::to_string(ratio));
  EXPECT_NEAR(ratio, 1.0, 0.10);
  // It stays stopped and on the floor.
  for (int k = 0; k < 200; ++k) bw.step();
  EXPECT_NEAR(bw.state().x[i].x - x0.x, travelled, 1e-3);
  EXPECT_NEAR(bw.state().x[i].y, x0.y, 0.01);
}

// The four-box column settles: after 2000 frames every box within 1 cm of its initial
// height and every speed below 0.05 m/s; it must also not have drifted sideways.
TEST(BulletWorld, BoxStackSettles) {
  const Scene scene = load_scene(scene_path("box-stack"));
  World world(scene);
  BulletWorld bw(world);
  const BodyState s0 = bw.state();
  std::uint64_t contacts = 0;
  for (int n = 1; n <= 2000; ++n) contacts = bw.step().contacts;
  std::string heights;
  int dynamic = 0;
  for (std::size_t i = 0; i < s0.size(); ++i) {
    if (s0.w[i] == 0.0f) continue;
    ++dynamic;
    const Vec3 x = bw.state().x[i], v = bw.state().v[i];
    heights += std::to_string(x.y) + " ";
    EXPECT_NEAR(x.y, s0.x[i].y, 0.01) << "body " << i;
    EXPECT_NEAR(x.x, s0.x[i].x, 0.01) << "body " << i;
    EXPECT_NEAR(x.z, s0.x[i].z, 0.01) << "body " << i;
    EXPECT_LT(length(v), 0.05f) << "body " << i;
  }
  EXPECT_EQ(dynamic, 4);
  // Floor-box plus three box-box manifolds.
  EXPECT_EQ(contacts, 4u);
  EXPECT_LT(bw.last_metrics().penetration_max, 0.01);
  std::printf("box-stack settled heights: %s(initial 0.1 0.3 0.5 0.7); pen max %.3g m\n",
              heights.c_str(), bw.last_metrics().penetration_max);
  RecordProperty("settled_heights", heights);
}

// ---- BulletSettings::shape (design.md section 15): the same meshes, or boxes -----------

namespace {

/// tests/data/bullet-static-mesh.json: a 0.08 m box dropped from y = 0.6 onto a static
/// bunny (scale 0.6, local AABB top 0.2924 m at y = 0), no walls. Empty scene when the
/// datasets are not fetched.
std::shared_ptr<const Model> static_mesh_model() {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  const std::string src = root ? root : ".";
  return build_model(load_scene(src + "/tests/data/bullet-static-mesh.json", src + "/datasets/cache"));
}

bool have_bunny() {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return std::ifstream(std::string(root ? root : ".") + "/datasets/cache/bunny.obj").good();
}

}  // namespace

// Hull mode (the default): the static bunny is Bullet's btBvhTriangleMeshShape. The box
// must come to rest on the mesh: its centre above the bunny's centre (it did not fall
// through; with no floor it would fall forever) and below where it rests on the bunny's
// AABB (0.2924 + 0.04 = 0.3324 m, the box mode's answer below): it touches the mesh's
// back, 5.5 cm under the AABB top (measured 0.2771 m, at rest from frame 740 of 900). Declared shapes:
// "mesh" for the static triangle mesh, "convex_hull" for the dynamic box.
TEST(BulletWorld, HullModeBoxRestsOnStaticTriangleMesh) {
  if (!have_bunny()) GTEST_SKIP() << "datasets not fetched (run datasets/fetch.sh)";
  const std::shared_ptr<const Model> model = static_mesh_model();
  BulletWorld bw(model, model->initial);
  ASSERT_EQ(bw.settings().shape, BulletShape::Hull);
  ASSERT_TRUE(bw.can_record());
  ASSERT_NE(bw.rotation_traits(), nullptr);
  EXPECT_EQ(bw.rotation_traits()->body_collision_shape, (std::vector<std::string>{"mesh", "convex_hull"}));
  EXPECT_NE(bw.collision_geometry().find("triangle mesh (static meshes)"), std::string::npos)
      << bw.collision_geometry();
  for (int f = 0; f < 900; ++f) bw.step();
  const Vec3 x = bw.state().x[1], v = bw.state().v[1];
  EXPECT_GT(x.y, 0.15f) << "the box fell into or through the static mesh";
  EXPECT_LT(x.y, 0.3324f - 0.01f) << "the box rests on the bunny's AABB, not on its triangles";
  EXPECT_LT(length(v), 0.05f) << "the box is not at rest";
  EXPECT_TRUE(bw.state().q.empty());  // translation only: no orientations
}

// Box mode (explicit): the same scene's box rests on the bunny's AABB box, centre at
// 0.2924 + 0.04 = 0.3324 m (measured 0.33245 m; within 2 mm), and
// Bullet records nothing (no declared geometry to judge against).
TEST(BulletWorld, BoxModeRestsOnTheAabb) {
  if (!have_bunny()) GTEST_SKIP() << "datasets not fetched (run datasets/fetch.sh)";
  const std::shared_ptr<const Model> model = static_mesh_model();
  BulletSettings boxes;
  boxes.shape = BulletShape::Box;
  BulletWorld bw(model, model->initial, BulletOptions(), boxes);
  EXPECT_FALSE(bw.can_record());
  EXPECT_EQ(bw.rotation_traits(), nullptr);
  EXPECT_EQ(bw.collision_geometry(), "bullet boxes equal to the AABBs (shape=box)");
  EXPECT_EQ(bw.midphase_name(), "bullet-box-box");
  for (int f = 0; f < 900; ++f) bw.step();
  EXPECT_NEAR(bw.state().x[1].y, 0.3324f, 0.002f);
}

// --bullet KEY=VALUE: hull and box parse, anything else is an InputError naming the key
// and what is allowed.
TEST(BulletWorld, SettingsParseAndRefuse) {
  BulletSettings s;
  apply_settings(s, {"shape=box"}, "--bullet");
  EXPECT_EQ(s.shape, BulletShape::Box);
  apply_settings(s, {"shape=hull"}, "--bullet");
  EXPECT_EQ(s.shape, BulletShape::Hull);
  try {
    apply_settings(s, {"shape=sphere"}, "--bullet");
    FAIL() << "shape=sphere accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("--bullet: shape='sphere' is not allowed; allowed: hull"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(apply_settings(s, {"margin=0"}, "--bullet"), InputError);
  EXPECT_THROW(apply_settings(s, {"shape"}, "--bullet"), InputError);
  EXPECT_EQ(s.solver_iterations, 10);  // Bullet's default
  apply_settings(s, {"iterations=20"}, "--bullet");
  EXPECT_EQ(s.solver_iterations, 20);
  for (const char* bad : {"iterations=0", "iterations=10001", "iterations=5x", "iterations="}) {
    try {
      apply_settings(s, {bad}, "--bullet");
      FAIL() << bad << " accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("allowed: an integer in [1, 10000]"), std::string::npos) << e.what();
    }
  }
}

// The solver's iterations reach Bullet: a box stack stepped 300 frames with 1 iteration per
// step sinks further into its supports than with 20 (each iteration removes part of the
// approach velocity), so the two runs' heights differ and the 1-iteration stack is lower.
TEST(BulletWorld, SolverIterationsSettingReachesTheSolver) {
  const Scene scene = load_scene(scene_path("box-stack"));
  World world(scene);
  BulletSettings one, many;
  one.solver_iterations = 1;
  many.solver_iterations = 20;
  BulletWorld a(world, one), b(world, many);
  for (int n = 1; n <= 300; ++n) {
    a.step();
    b.step();
  }
  double sum_a = 0.0, sum_b = 0.0;
  for (std::size_t i = 0; i < a.state().size(); ++i) {
    if (a.state().w[i] == 0.0f) continue;
    sum_a += a.state().x[i].y;
    sum_b += b.state().x[i].y;
  }
  EXPECT_NE(sum_a, sum_b);
  EXPECT_LT(sum_a, sum_b);
}

}  // namespace octocd_test_bullet_world
