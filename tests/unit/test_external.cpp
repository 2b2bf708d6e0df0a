// The C++ API for another engine's frames (octocd/external.hpp, issue 11): the same
// validators that judge octocd's engines judge frames given from outside; conventions
// broken in the data are errors, not verdicts.
#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "octocd/error.hpp"
#include "octocd/external.hpp"
#include "octocd/world.hpp"
#include "unit/test_scenes.hpp"

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
  EXPECT_TRUE(find(rs, "candidate-sets").applicable);
  EXPECT_TRUE(find(rs, "contact-normals").applicable);
}

TEST(External, MissingAndExtraPairsAreNamed) {
  TwoBoxes t;
  t.rec.pairs = {};
  ValidationResult r = find(validate_frame(t.bodies, t.rec), "candidate-sets");
  EXPECT_FALSE(r.pass);
  EXPECT_NE(r.detail.find("frame 4: engine 'external' misses pair (1, 2)"), std::string::npos) << r.detail;
  t.rec.pairs = {{0, 1}, {1, 2}};
  r = find(validate_frame(t.bodies, t.rec), "candidate-sets");
  EXPECT_FALSE(r.pass);
  EXPECT_NE(r.detail.find("adds pair (0, 1)"), std::string::npos) << r.detail;
}

TEST(External, ANormalFromAToBFailsAndSaysTheConvention) {
  TwoBoxes t;
  t.rec.contacts[0].normal = {1, 0, 0};
  const ValidationResult r = find(validate_frame(t.bodies, t.rec), "contact-normals");
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
  const ValidationResult r = find(validate_frame(bodies, rec), "contact-normals");
  EXPECT_TRUE(r.applicable && r.pass) << r.detail;
  EXPECT_NE(r.detail.find("mesh-mesh 1.000 of 1"), std::string::npos) << r.detail;
}

// The records octocd's CPU engine makes, given as another engine's (pairs, contacts with
// pair/normal/depth/impulses only, states): every applicable validator passes; the
// engine's broadphase losing a pair fails candidate-sets on the same path.
TEST(External, TheCpuEnginesFramesPassAndAPlantedLossFails) {
  for (const bool plant : {false, true}) {
    const Scene scene = octocd::test::mixed_boxes();
    World world(scene);
    PlantedFaults faults;
    faults.broadphase_drops_pair = plant;
    world.plant_faults(faults);
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
        reported.jt = c.jt;
        c = reported;
      }
      v.observe(rec, f % 5 == 0);
    }
    const auto rs = v.results();
    if (!plant) {
      for (const auto& r : rs) EXPECT_TRUE(r.pass || !r.applicable) << r.name << ": " << r.detail;
      for (const char* name : {"candidate-sets", "contact-normals", "non-penetration", "friction", "conservation"})
        EXPECT_TRUE(find(rs, name).applicable) << name;
    } else {
      const ValidationResult r = find(rs, "candidate-sets");
      EXPECT_FALSE(r.pass);
      EXPECT_NE(r.detail.find("engine 'cpu-as-external' misses pair"), std::string::npos) << r.detail;
    }
  }
}
