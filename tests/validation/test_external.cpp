// The C++ API for another engine's frames (octocd/external.hpp, issue 11): the same
// validators that judge octocd's engines judge frames given from outside; conventions
// broken in the data are errors, not verdicts.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "faults/planted_faults.hpp"
#include "octocd/error.hpp"
#include "octocd/external.hpp"
#include "octocd/world.hpp"
#include "support/external_trace.hpp"
#include "support/test_scenes.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_external {

using namespace octocd;

namespace {

ValidationResult find(const std::vector<ValidationResult>& rs, const std::string& name) {
  for (const auto& r : rs)
    if (r.name == name) return r;
  ADD_FAILURE() << "no result named " << name;
  return {};
}

/// Two unit-mass boxes of half side 0.1 overlapping by 2 cm along x, and a static floor.
struct TwoBoxes {
  ExternalBodies bodies;
  FrameRecord rec;
  TwoBoxes() {
    bodies.local_boxes = {{{-1, -0.1f, -1}, {1, 0.1f, 1}}, {{-0.1f, -0.1f, -0.1f}, {0.1f, 0.1f, 0.1f}},
                          {{-0.1f, -0.1f, -0.1f}, {0.1f, 0.1f, 0.1f}}};
    bodies.inverse_mass = {0, 1, 1};
    const std::vector<Vec3> x = {{0, -0.1f, 0}, {0, 1, 0}, {0.18f, 1, 0}};
    rec.frame = 4;
    for (std::size_t i = 0; i < x.size(); ++i) rec.aabbs.push_back(translated(bodies.local_boxes[i], x[i]));
    rec.pairs = {{1, 2}};
    ContactRecord c;
    c.pair = {1, 2};
    c.normal = {-1, 0, 0};  // from body 2 to body 1
    c.depth = 0.02f;
    rec.contacts = {c};
  }
};

}  // namespace

TEST(External, AFrameThatKeepsTheConventionsPasses) {
  TwoBoxes t;
  const auto rs = validate_frame(t.bodies, t.rec);
  for (const auto& r : rs) EXPECT_TRUE(r.pass || !r.applicable) << r.name << ": " << r.detail;
  EXPECT_TRUE(find(rs, "broadphase-completeness").applicable);
  EXPECT_TRUE(find(rs, "contact-geometry").applicable);
  // Another engine is judged by the physics tier; the model tier is n/a with the reason.
  EXPECT_FALSE(find(rs, "candidate-sets").applicable);
  EXPECT_NE(find(rs, "non-penetration-eq14").detail.find("does not claim design.md section 6"), std::string::npos);
}

TEST(External, MissingAndExtraPairsAreNamed) {
  TwoBoxes t;
  t.rec.pairs = {};
  ValidationResult r = find(validate_frame(t.bodies, t.rec), "broadphase-completeness");
  EXPECT_FALSE(r.pass);
  EXPECT_NE(r.detail.find("frame 4: engine 'external' misses pair (1, 2)"), std::string::npos) << r.detail;
  // An extra pair (a conservative broadphase) is counted, not failed (design.md section 13.1).
  t.rec.pairs = {{0, 1}, {1, 2}};
  r = find(validate_frame(t.bodies, t.rec), "broadphase-completeness");
  EXPECT_TRUE(r.pass) << r.detail;
  EXPECT_NE(r.detail.find("2 candidates per true pair"), std::string::npos) << r.detail;
  // An engine that declares an exact AABB broadphase is held to flat's set.
  t.bodies.physics.broadphase_exact = true;
  r = find(validate_frame(t.bodies, t.rec), "broadphase-completeness");
  EXPECT_FALSE(r.pass) << r.detail;
  EXPECT_NE(r.detail.find("(0, 1)"), std::string::npos) << r.detail;
}

TEST(External, AnExactBroadphaseIsHeldToFlatsSetOnItsOwnBoxesWhateverTheirMargin) {
  // The engine's boxes are the posed boxes: flat's set on them is read off the judge's
  // candidates (its boxes grown by the reach hold them). Missing and extra pairs named.
  TwoBoxes t;
  t.bodies.physics.broadphase_exact = true;
  ValidationResult r = find(validate_frame(t.bodies, t.rec), "broadphase-completeness");
  EXPECT_TRUE(r.pass) << r.detail;
  t.rec.pairs = {};
  r = find(validate_frame(t.bodies, t.rec), "broadphase-completeness");
  EXPECT_FALSE(r.pass);
  EXPECT_NE(r.detail.find("misses pair (1, 2) of flat on its world AABBs (1 missing, 0 extra)"), std::string::npos)
      << r.detail;
  // Boxes grown by a 0.5 m margin, wider than the judge's reach: pairs (0, 1) and (0, 2)
  // overlap on the engine's boxes only (the shapes are 0.9 m apart), so flat's set comes
  // from its own search; an engine that reports (1, 2) alone misses them.
  TwoBoxes wide;
  wide.bodies.physics.broadphase_exact = true;
  for (Aabb& b : wide.rec.aabbs) b = expanded(b, 0.5f);
  r = find(validate_frame(wide.bodies, wide.rec), "broadphase-completeness");
  EXPECT_FALSE(r.pass);
  EXPECT_NE(r.detail.find("misses pair (0, 1) of flat on its world AABBs (2 missing, 0 extra)"), std::string::npos)
      << r.detail;
  wide.rec.pairs = {{0, 1}, {0, 2}, {1, 2}};
  r = find(validate_frame(wide.bodies, wide.rec), "broadphase-completeness");
  EXPECT_TRUE(r.pass) << r.detail;
}

TEST(External, ANormalFromAToBFailsAndSaysTheConvention) {
  TwoBoxes t;
  t.rec.contacts[0].normal = {1, 0, 0};
  const ValidationResult r = find(validate_frame(t.bodies, t.rec), "contact-geometry");
  EXPECT_FALSE(r.pass);
  EXPECT_NE(r.detail.find("from B to A"), std::string::npos) << r.detail;
}

TEST(External, BrokenConventionsAreErrorsNamingFieldAndFrame) {
  auto message = [](const TwoBoxes& t) {
    try {
      validate_frame(t.bodies, t.rec);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  TwoBoxes swapped;
  swapped.rec.pairs = {{2, 1}};
  EXPECT_NE(message(swapped).find("pairs: frame 4: row 0 is (2, 1): a >= b"), std::string::npos)
      << message(swapped);
  TwoBoxes range;
  range.rec.pairs = {{1, 3}};
  EXPECT_NE(message(range).find("out of range"), std::string::npos) << message(range);
  TwoBoxes unit;
  unit.rec.contacts[0].normal = {-2, 0, 0};
  EXPECT_NE(message(unit).find("contacts.normal: frame 4"), std::string::npos) << message(unit);
  TwoBoxes sizes;
  sizes.rec.aabbs.pop_back();
  EXPECT_NE(message(sizes).find("aabbs: frame 4: 2 boxes for 3 bodies"), std::string::npos) << message(sizes);
  TwoBoxes depth;
  depth.rec.contacts[0].depth = -0.01f;
  EXPECT_NE(message(depth).find("contacts.depth"), std::string::npos) << message(depth);
}

TEST(External, MeshBodiesGetReferenceNormals) {
  ExternalBodies bodies;
  auto sphere = std::make_shared<const Mesh>(make_icosphere(0.1f, 2));
  const Aabb local = mesh_bounds(*sphere);
  bodies.local_boxes = {local, local};
  bodies.meshes = {sphere, sphere};
  FrameRecord rec;
  rec.frame = 1;
  rec.aabbs = {translated(local, {0, 0, 0}), translated(local, {0, 0.19f, 0})};
  rec.pairs = {{0, 1}};
  ContactRecord c;
  c.pair = {0, 1};
  c.normal = {0, -1, 0};
  c.depth = 0.01f;
  rec.contacts = {c};
  const ValidationResult r = find(validate_frame(bodies, rec), "contact-geometry");
  EXPECT_TRUE(r.applicable && r.pass) << r.detail;
  EXPECT_NE(r.detail.find("1 rows judged"), std::string::npos) << r.detail;
}

// The records octocd's CPU engine makes, given as another engine's (pairs, contacts with
// pair/normal/depth/impulses only, states): every applicable validator passes; the
// engine's broadphase losing a pair fails candidate-sets on the same path.
TEST(External, TheCpuEnginesFramesPassAndAPlantedLossFails) {
  for (const bool plant : {false, true}) {
    const Scene scene = octocd::test::mixed_boxes();
    octocd::test::PlantedFaults faults;
    faults.broadphase_drops_pair = plant;
    const std::unique_ptr<Engine> engine = octocd::test::cpu_engine(scene, faults);
    Engine& world = *engine;
    world.set_recording(true);
    ExternalBodies bodies;
    bodies.scene_json = scene.json;
    for (std::size_t i = 0; i < world.bodies().size(); ++i) {
      bodies.local_boxes.push_back(world.model().local_box(i));
      bodies.inverse_mass.push_back(world.model().initial.w[i]);
    }
    ExternalOptions options;
    options.engine = "cpu-as-external";
    ExternalValidator v(bodies, options);
    for (int f = 1; f <= 150; ++f) {
      world.step();
      FrameRecord rec = world.record();
      for (ContactRecord& c : rec.contacts) {  // keep only what another engine reports
        ContactRecord reported;
        reported.pair = c.pair;
        reported.normal = c.normal;
        reported.depth = c.depth;
        reported.jn = c.jn;
        reported.jt = -c.jt;  // the trace convention: along -v_t (octocd's J_t is along +t, design.md section 6)
        c = reported;
      }
      v.observe(rec, f % 5 == 0);
    }
    const auto rs = v.results();
    if (!plant) {
      for (const auto& r : rs) EXPECT_TRUE(r.pass || !r.applicable) << r.name << ": " << r.detail;
      for (const char* name : {"broadphase-completeness", "contact-completeness", "contact-geometry", "penetration",
                               "friction", "conservation"})
        EXPECT_TRUE(find(rs, name).applicable) << name;
    } else {
      const ValidationResult r = find(rs, "broadphase-completeness");
      EXPECT_FALSE(r.pass);
      EXPECT_NE(r.detail.find("engine 'cpu-as-external' misses pair"), std::string::npos) << r.detail;
    }
  }
}

// ---- External traces version 2 (design.md section 13, issue 17) through the C++ API -----

namespace {

/// A temporary file path for one test's trace, removed with the object.
struct TempTrace {
  std::filesystem::path path;
  explicit TempTrace(const octocd::test::Trace& t) {
    path = std::filesystem::temp_directory_path() /
           ("octocd-external-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name() + ".h5");
    t.write(path.string());
  }
  ~TempTrace() { std::filesystem::remove(path); }
};

/// A scene of the test trace's three boxes with its own response and time step.
const char* const kThreeBoxes = R"({"name": "three", "domain": {"min": [-1, -2, -1], "max": [1, 1, 1]},
    "dt": 0.002, "gravity": [0, -5, 0], "walls": "none",
    "response": {"mu_static": 0.35, "restitution": 0.1, "slop": 0.002},
    "groups": [{"shape": {"box": [0.1, 0.1, 0.1]}, "count": 3, "positions": [[0, -1, 0], [0, 0, 0], [0.199, 0, 0]]}]})";

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

}  // namespace

// Every field of a version 2 trace lands in the FrameRecord and the bodies' physics.
TEST(ExternalV2, RoundTripEveryField) {
  const octocd::test::Trace t = octocd::test::Trace::make_v2();
  TempTrace file(t);
  ExternalTrace in(file.path.string());
  const ExternalTraceInfo& info = in.info();
  EXPECT_EQ(info.version, 2);
  EXPECT_TRUE(info.has_rotation && info.has_points && info.has_states && info.has_contacts && info.has_pairs);
  EXPECT_FALSE(info.has_aabbs);
  EXPECT_EQ(info.frames, 3);
  const PhysicsBodies& p = in.bodies().physics;
  ASSERT_EQ(p.inertia.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i)
    for (std::size_t k = 0; k < 9; ++k) EXPECT_EQ(p.inertia[i][k], static_cast<double>(t.inertia[9 * i + k])) << i << k;
  EXPECT_EQ(p.body_friction, t.friction);
  EXPECT_EQ(p.body_restitution, t.restitution);
  EXPECT_DOUBLE_EQ(p.mu, 0.4);
  EXPECT_DOUBLE_EQ(p.restitution, 0.2);
  EXPECT_EQ(p.combine, MaterialCombine::Min);
  EXPECT_EQ(p.restitution_combine, MaterialCombine::Max);
  EXPECT_DOUBLE_EQ(p.contact_margin, 0.01);
  EXPECT_TRUE(p.broadphase_exact);
  EXPECT_EQ(p.contact_geometry, ContactGeometry::Aabb);
  EXPECT_DOUBLE_EQ(p.slop, 0.001);  // no scene: the default
  auto vec = [](const std::vector<float>& a, std::size_t row, std::size_t i) {
    return Vec3{a[(row * 3 + i) * 3], a[(row * 3 + i) * 3 + 1], a[(row * 3 + i) * 3 + 2]};
  };
  auto quat = [&](std::size_t row, std::size_t i) {
    const float* q = &t.orientation[(row * 3 + i) * 4];
    return Quat{q[0], q[1], q[2], q[3]};
  };
  auto same = [](Quat a, Quat b) { return a.w == b.w && a.x == b.x && a.y == b.y && a.z == b.z; };
  std::size_t row = 0;  // contact row over all frames
  for (std::int64_t f = 1; f <= 3; ++f) {
    const FrameRecord rec = in.frame(f);
    const std::size_t r = static_cast<std::size_t>(f);
    EXPECT_EQ(rec.frame, f);
    EXPECT_TRUE(rec.aabbs.empty());  // never made up by the reader
    EXPECT_TRUE(rec.manifolds && rec.has_points && rec.has_pairs);
    EXPECT_FALSE(rec.has_contact_terms);  // pair, normal, depth, jn, jt, point only
    ASSERT_EQ(rec.q_pre.size(), 3u);
    ASSERT_EQ(rec.x_det.size(), 3u);
    ASSERT_EQ(rec.q_det.size(), 3u);
    for (std::size_t i = 0; i < 3; ++i) {
      EXPECT_EQ(rec.x_pre[i], vec(t.position, r - 1, i));
      EXPECT_EQ(rec.x_post[i], vec(t.position, r, i));
      EXPECT_EQ(rec.v_pre[i], vec(t.velocity, r - 1, i));
      EXPECT_EQ(rec.v_post[i], vec(t.velocity, r, i));
      EXPECT_TRUE(same(rec.q_pre[i], quat(r - 1, i))) << f << " " << i;
      EXPECT_TRUE(same(rec.q_post[i], quat(r, i))) << f << " " << i;
      EXPECT_EQ(rec.w_pre[i], vec(t.angular_velocity, r - 1, i));
      EXPECT_EQ(rec.w_post[i], vec(t.angular_velocity, r, i));
      // detection "pre-step": the pose of row f-1
      EXPECT_EQ(rec.x_det[i], rec.x_pre[i]);
      EXPECT_TRUE(same(rec.q_det[i], rec.q_pre[i]));
    }
    EXPECT_EQ(rec.pairs, (std::vector<Pair>{{1, 2}}));
    const std::size_t rows = static_cast<std::size_t>(t.contact_offsets[r] - t.contact_offsets[r - 1]);
    ASSERT_EQ(rec.contacts.size(), rows);
    for (const ContactRecord& c : rec.contacts) {
      EXPECT_EQ(c.pair, (Pair{t.contact_pair[2 * row], t.contact_pair[2 * row + 1]}));
      EXPECT_EQ(c.normal, (Vec3{t.normal[3 * row], t.normal[3 * row + 1], t.normal[3 * row + 2]}));
      EXPECT_EQ(c.point, (Vec3{t.point[3 * row], t.point[3 * row + 1], t.point[3 * row + 2]}));
      EXPECT_EQ(c.depth, t.depth[row]);
      EXPECT_EQ(c.jn, t.jn[row]);
      EXPECT_EQ(c.jt, t.jt[row]);
      ++row;
    }
  }
  EXPECT_TRUE(in.info().manifolds);  // frame 1 has two rows of (1, 2)
  EXPECT_NE(error_of([&] { in.frame(4); }).find("frame 4: out of range; allowed: 1 .. 3"), std::string::npos);
}

// Defaults: inertia derived as a solid box of the local AABB (static: zeros), materials and
// slop from the scene's response; detection "integrated" gives design.md section 4.1's pose.
TEST(ExternalV2, DefaultsAndTheIntegratedDetectionPose) {
  octocd::test::Trace t = octocd::test::Trace::make_v2();
  t.inertia.clear();
  t.friction.clear();
  t.restitution.clear();
  t.number_attrs.clear();
  t.string_attrs = {{"detection", "integrated"}};
  for (std::size_t k = 0; k < t.velocity.size(); ++k) t.velocity[k] = 0.25f * static_cast<float>(k % 3);
  {
    TempTrace file(t);
    ExternalTrace in(file.path.string());
    const PhysicsBodies& p = in.bodies().physics;
    ASSERT_EQ(p.inertia.size(), 3u);
    const double d = 1.0 / 12.0 * (0.2 * 0.2 + 0.2 * 0.2);  // 1 kg, sides 0.2
    for (std::size_t k = 0; k < 9; ++k) {
      EXPECT_EQ(p.inertia[0][k], 0.0);
      EXPECT_NEAR(p.inertia[1][k], k % 4 == 0 ? d : 0.0, 1e-9) << k;
    }
    EXPECT_TRUE(p.body_friction.empty() && p.body_restitution.empty());
    EXPECT_DOUBLE_EQ(p.mu, 0.6);  // version 1's defaults without a scene
    EXPECT_DOUBLE_EQ(p.restitution, 0.5);
    EXPECT_EQ(p.combine, MaterialCombine::Product);
    EXPECT_DOUBLE_EQ(p.contact_margin, 0.02);
    EXPECT_FALSE(p.broadphase_exact);
    EXPECT_EQ(p.contact_geometry, ContactGeometry::Shape);
    const FrameRecord rec = in.frame(2);
    for (std::size_t i = 0; i < 3; ++i) {
      Vec3 x = rec.x_pre[i], v = rec.v_pre[i];
      integrate(x, v, t.inverse_mass[i], Vec3{0, 0, 0}, Vec3{}, 0.001f);  // the trace: no gravity, default dt
      EXPECT_EQ(rec.x_det[i], x) << i;
      if (t.inverse_mass[i] > 0.0f) {
        EXPECT_FALSE(rec.x_det[i] == rec.x_pre[i]) << i;  // moved by dt v
      }
    }
  }
  // With a scene: its response's mu_s, e and slop; its dt and gravity for "integrated".
  t.string_attrs["scene"] = kThreeBoxes;
  TempTrace file(t);
  ExternalTrace in(file.path.string());
  EXPECT_DOUBLE_EQ(in.bodies().physics.mu, 0.35f);
  EXPECT_DOUBLE_EQ(in.bodies().physics.restitution, 0.1f);
  EXPECT_DOUBLE_EQ(in.bodies().physics.slop, 0.002f);
  const FrameRecord rec = in.frame(3);
  for (std::size_t i = 0; i < 3; ++i) {
    Vec3 x = rec.x_pre[i], v = rec.v_pre[i];
    integrate(x, v, t.inverse_mass[i], Vec3{0, -5, 0}, Vec3{}, 0.002f);
    EXPECT_EQ(rec.x_det[i], x) << i;
  }
}

// A version 1 trace reads as before: no rotation, no detection pose, one contact per pair.
TEST(ExternalV2, Version1ReadsAsBefore) {
  TempTrace file(octocd::test::Trace{});
  ExternalTrace in(file.path.string());
  EXPECT_EQ(in.info().version, 1);
  EXPECT_FALSE(in.info().has_rotation || in.info().has_points);
  const FrameRecord rec = in.frame(1);
  EXPECT_TRUE(rec.q_pre.empty() && rec.w_pre.empty() && rec.x_det.empty() && rec.q_det.empty());
  EXPECT_FALSE(rec.manifolds || rec.has_points);
  EXPECT_EQ(rec.aabbs.size(), 3u);
  EXPECT_EQ(in.bodies().physics.inertia.size(), 0u);
}

// A version 1 trace with a scene: the physics tier gets the scene's mu_s, e and slop, not
// the defaults (issue 17: the default 0.6 against an engine's 1.0 gave a wrong FAIL).
TEST(ExternalV2, Version1TakesMaterialsFromTheScene) {
  octocd::test::Trace t;
  t.string_attrs["scene"] = kThreeBoxes;
  TempTrace file(t);
  ExternalTrace in(file.path.string());
  EXPECT_DOUBLE_EQ(in.bodies().physics.mu, 0.35f);
  EXPECT_DOUBLE_EQ(in.bodies().physics.restitution, 0.1f);
  EXPECT_DOUBLE_EQ(in.bodies().physics.slop, 0.002f);
  EXPECT_TRUE(in.frame(1).x_det.empty());  // version 1: octocd's rule, from the AABBs
}

// check_frame_record covers the rotation fields for C++ API users.
TEST(ExternalV2, CheckFrameRecordCoversRotationFields) {
  TwoBoxes t;
  const Quat turned = axis_angle({0, 0, 1}, 0.3f);
  auto rotating = [&] {
    TwoBoxes r;
    r.rec.x_pre = r.rec.x_post = {{0, -0.1f, 0}, {0, 1, 0}, {0.18f, 1, 0}};
    r.rec.v_pre = r.rec.v_post = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
    r.rec.q_pre = r.rec.q_post = {Quat{}, turned, Quat{}};
    r.rec.w_pre = r.rec.w_post = {{0, 0, 0}, {0, 0, 1}, {0, 0, 0}};
    r.rec.x_det = r.rec.x_pre;
    r.rec.q_det = r.rec.q_pre;
    return r;
  };
  EXPECT_EQ(error_of([&] { check_frame_record(rotating().rec, 3, "api"); }), "no error");
  TwoBoxes q = rotating();
  q.rec.q_post[1].w *= 1.01f;
  EXPECT_NE(error_of([&] { check_frame_record(q.rec, 3, "api"); })
                .find("api: q_post: frame 4: body 1 after the step is"),
            std::string::npos);
  TwoBoxes no_w = rotating();
  no_w.rec.w_pre.clear();
  no_w.rec.w_post.clear();
  EXPECT_NE(error_of([&] { check_frame_record(no_w.rec, 3, "api"); })
                .find("w_pre: frame 4: orientations without angular velocities"),
            std::string::npos);
  TwoBoxes half = rotating();
  half.rec.q_post.clear();
  EXPECT_NE(error_of([&] { check_frame_record(half.rec, 3, "api"); }).find("q_post: frame 4: missing (q_pre given)"),
            std::string::npos);
  TwoBoxes det = rotating();
  det.rec.q_det.pop_back();
  EXPECT_NE(error_of([&] { check_frame_record(det.rec, 3, "api"); }).find("q_det: frame 4: 2 rows for 3 bodies"),
            std::string::npos);
  TwoBoxes manifold = rotating();
  manifold.rec.manifolds = true;
  manifold.rec.has_points = true;
  ContactRecord c = manifold.rec.contacts[0];
  c.point = {0.09f, 1, 0};
  manifold.rec.contacts = {c, c, c};
  EXPECT_EQ(error_of([&] { check_frame_record(manifold.rec, 3, "api"); }), "no error");
  ContactRecord other = c;
  other.pair = {0, 1};
  manifold.rec.contacts = {other, c, other};
  EXPECT_NE(error_of([&] { check_frame_record(manifold.rec, 3, "api"); })
                .find("contacts.pair: frame 4: row 2 is (0, 1) again after (1, 2): manifold rows of one pair not "
                      "consecutive"),
            std::string::npos);
  manifold.rec.manifolds = false;  // one row per pair: repeated rows are duplicates
  manifold.rec.contacts = {c, c};
  EXPECT_NE(error_of([&] { check_frame_record(manifold.rec, 3, "api"); }).find("duplicated"), std::string::npos);
  manifold.rec.manifolds = true;
  manifold.rec.contacts[1].point.y = NAN;
  EXPECT_NE(error_of([&] { check_frame_record(manifold.rec, 3, "api"); }).find("contacts.point: frame 4: row 1"),
            std::string::npos);
}

// PhysicsBodies from the C++ API are checked when the validator is built.
TEST(ExternalV2, PhysicsBodiesAreChecked) {
  TwoBoxes t;
  t.bodies.physics.inertia = {box_inertia(t.bodies.local_boxes[0], 0.0f), box_inertia(t.bodies.local_boxes[1], 1.0f),
                              box_inertia(t.bodies.local_boxes[2], 1.0f)};
  EXPECT_EQ(error_of([&] { ExternalValidator v(t.bodies, {}); }), "no error");
  t.bodies.physics.inertia[2][1] = 0.01;  // I[0][1] without I[1][0]
  EXPECT_NE(error_of([&] { ExternalValidator v(t.bodies, {}); }).find("physics.inertia: body 2:"), std::string::npos);
  t.bodies.physics.inertia[2] = box_inertia(t.bodies.local_boxes[2], 1.0f);
  t.bodies.physics.body_restitution = {0.5f, 1.5f, 0.5f};
  EXPECT_NE(error_of([&] { ExternalValidator v(t.bodies, {}); }).find("physics.body_restitution: body 1: 1.5"),
            std::string::npos);
}

// With a scene, a body frame whose origin is the centre of mass (not the box centre)
// translates the scene's shape: the mesh moves with it; sizes must still match.
TEST(ExternalV2, SceneShapesTranslateToTheGivenLocalBoxes) {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  const Scene scene = load_scene(std::string(root ? root : ".") + "/tests/data/spheres-drop.json");
  ExternalBodies bodies;
  bodies.scene_json = scene.json;
  World world(scene);
  const std::size_t n = world.bodies().size();
  const std::size_t sphere = n - 1;  // the last body: an icosphere
  for (std::size_t i = 0; i < n; ++i) bodies.local_boxes.push_back(world.model().local_box(i));
  const Vec3 offset{0.01f, -0.02f, 0.005f};
  bodies.local_boxes[sphere] = translated(bodies.local_boxes[sphere], offset);
  ExternalValidator v(bodies, {});
  const Model& m = v.model();
  const Aabb& moved = m.local_box(sphere);
  EXPECT_NEAR(moved.min.x, bodies.local_boxes[sphere].min.x, 1e-6);
  EXPECT_NEAR(moved.max.y, bodies.local_boxes[sphere].max.y, 1e-6);
  const Shape& shape = m.shapes[m.bodies[sphere].shape];
  ASSERT_TRUE(shape.mesh && shape.octree);
  const Aabb mb = mesh_bounds(*shape.mesh);
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(mb.min[k], moved.min[k], 1e-5) << k;
    EXPECT_NEAR(mb.max[k], moved.max[k], 1e-5) << k;
  }
  EXPECT_EQ(m.bodies[0].shape, world.model().bodies[0].shape);  // untouched bodies keep theirs
  // A box of another size is not the scene's shape.
  bodies.local_boxes[sphere].max.x += 0.01f;
  EXPECT_NE(error_of([&] { ExternalValidator w(bodies, {}); }).find("local_boxes: body " + std::to_string(sphere)),
            std::string::npos);
}

}  // namespace octocd_test_external
