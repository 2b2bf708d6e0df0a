// The host estimate of the CUDA engine's device memory (cuda_device_bytes_needed,
// gpu/include/octocd/cuda_world.hpp; issue 8, "bad input at scale"): it needs no device
// and exists in builds without CUDA, so these tests run everywhere. The GPU side (the
// estimate against the engine's memory_bytes, the check at construction, the CLI's exit 1)
// is in tests/gpu/test_cuda_world.cpp. Also the host bookkeeping of recorded batches
// (gpu/src/record_ring.hpp: CudaSettings::record_batch), which needs no device either.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "octocd/cuda_world.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/vertex_blocks.hpp"
#include "octocd/worlds.hpp"
#include "record_ring.hpp"  // gpu/src: plain C++

using namespace octocd;

namespace {

BroadPhaseConfig bp(const std::string& name, int depth = 2) {
  BroadPhaseConfig c;
  c.name = name;
  c.octree_depth = depth;
  return c;
}

/// Every device broadphase, the octrees with a fixed and an automatic depth.
std::vector<BroadPhaseConfig> device_broadphases() {
  return {bp("flat"), bp("octree"), bp("octree", -1), bp("octree-strict"), bp("octree-strict", -1),
          bp("spatial-hash"), bp("lbvh")};
}

std::string label(const BroadPhaseConfig& c) { return c.name + " depth " + std::to_string(c.octree_depth); }

/// Bytes of the engine's buffers of one element per body (CudaWorld::Impl: x, v, x_saved,
/// v_saved, w, local, shape, aabb) and of n + 1 elements (bp_count, bp_offset,
/// body_begin), counted here from the element types, apart from the estimate's own code.
std::uint64_t per_body_buffers(std::uint64_t n) {
  return n * (4 * sizeof(Vec3) + sizeof(float) + sizeof(Aabb) + sizeof(std::uint32_t) + sizeof(Aabb)) +
         3 * (n + 1) * sizeof(std::uint32_t);
}

/// The message of the InputError that `f` throws, "" when it throws none.
template <class F>
std::string input_error(F f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

/// A model of `count` bodies of one shape (JSON members of a shape object) in a 2 m box.
std::shared_ptr<const Model> model_of(const std::string& shape, int count) {
  return build_model(parse_scene(R"({"name": "fp", "domain": {"min": [-1, 0, -1], "max": [1, 2, 1]},
      "walls": "none", "broadphase": {"name": "octree-strict", "depth": "auto"},
      "groups": [{"name": "b", "shape": )" + shape + R"(, "count": )" + std::to_string(count) +
                                     R"(, "layout": {"type": "grid", "min": [-0.9, 0.1, -0.9], "max": [0.9, 1.9, 0.9]}}]})",
                                 "fp.json"));
}

}  // namespace

// Linear in the body count (every buffer is a multiple of n plus a constant), with a
// slope of at least the per-body buffers, and at least their sum at every size.
TEST(CudaFootprint, LinearInBodyCountAndCoversThePerBodyBuffers) {
  for (const BroadPhaseConfig& c : device_broadphases()) {
    SCOPED_TRACE(label(c));
    for (std::uint64_t n : {1ull, 1000ull, 100000ull, 1000000ull, 10000000ull, 500000000ull}) {
      const std::uint64_t f1 = cuda_device_bytes_needed(n, c);
      const std::uint64_t f2 = cuda_device_bytes_needed(2 * n, c);
      const std::uint64_t f4 = cuda_device_bytes_needed(4 * n, c);
      if (c.name == "octree") {
        // Linear within 5%: the block table is the power of two >= 2 n (steps of at most
        // 2 entries per body).
        const double d2 = static_cast<double>(f4 - f2), d1 = 2.0 * static_cast<double>(f2 - f1);
        EXPECT_NEAR(d2, d1, 0.05 * d1) << "not linear around n = " << n;
      } else {
        EXPECT_EQ(f4 - f2, 2 * (f2 - f1)) << "not linear around n = " << n;
      }
      EXPECT_GE(f1, per_body_buffers(n)) << "n = " << n;
      EXPECT_GE(f2 - f1, per_body_buffers(2 * n) - per_body_buffers(n)) << "slope below the per-body buffers, n = " << n;
      // Per body: the per-body buffers, 2 candidate pairs (about 214 bytes each) and 8
      // work-list items (16 bytes each) of the first capacities, the broadphase's scratch:
      // under 2 KiB, and over the 116 bytes of the per-body buffers alone.
      EXPECT_LT(f2 - f1, 2048 * n) << "n = " << n;
      EXPECT_GT(f2 - f1, 500 * n) << "n = " << n;
    }
  }
  // 100k bodies, `flat`: about 70 MB (the GPU test compares this with the engine's own count).
  const std::uint64_t f = cuda_device_bytes_needed(100000, bp("flat"));
  EXPECT_GT(f, 60000000u);
  EXPECT_LT(f, 80000000u);
  // The strict octree's automatic depth needs per-body extents (a double and a flag).
  EXPECT_EQ(cuda_device_bytes_needed(1000, bp("octree-strict", -1)) - cuda_device_bytes_needed(1000, bp("octree-strict")),
            1000u * (sizeof(double) + sizeof(std::uint32_t)));
}

// The cuda engine indexes bodies with 32-bit integers: more than 2^31 - 1 is bad input.
TEST(CudaFootprint, MoreThan2Pow31Minus1BodiesIsAnInputError) {
  for (const BroadPhaseConfig& c : device_broadphases()) {
    SCOPED_TRACE(label(c));
    EXPECT_EQ(input_error([&] { (void)cuda_device_bytes_needed(kCudaMaxBodies, c); }), "");
    for (std::uint64_t n : {2147483648ull, 4294967296ull, 1000000000000ull}) {
      const std::string msg = input_error([&] { (void)cuda_device_bytes_needed(n, c); });
      EXPECT_NE(msg.find("the cuda engine takes at most 2147483647 (2^31 - 1) bodies"), std::string::npos) << msg;
      EXPECT_NE(msg.find("this model has " + std::to_string(n)), std::string::npos) << msg;
    }
  }
}

TEST(CudaFootprint, UnknownBroadphaseIsAnInputError) {
  for (const std::string name : {"bullet-dbvt", "fcl-dynamic-aabb", "no-such"}) {
    const std::string msg = input_error([&] { (void)cuda_device_bytes_needed(10, bp(name)); });
    EXPECT_NE(msg.find("'" + name + "' is not available on the cuda engine"), std::string::npos) << msg;
    EXPECT_NE(msg.find("flat, octree, octree-strict, spatial-hash, lbvh"), std::string::npos) << msg;
  }
}

// The Model overload: the count overload plus the model's shapes (a mesh's octree
// vertices, cells and vertex block boxes), with the scene's broadphase depth.
TEST(CudaFootprint, ModelAddsItsShapesAndUsesTheScenesDepth) {
  const int n = 64;
  const auto boxes = model_of(R"({"box": [0.05, 0.05, 0.05]})", n);
  const auto spheres = model_of(R"({"icosphere": {"radius": 0.05, "subdivisions": 3}})", n);
  ASSERT_EQ(boxes->initial.size(), static_cast<std::size_t>(n));
  ASSERT_EQ(spheres->initial.size(), static_cast<std::size_t>(n));
  const Shape& s = spheres->shapes.at(spheres->bodies.at(0).shape);
  ASSERT_TRUE(s.octree) << "an icosphere is a mesh with an octree";
  const std::uint64_t mesh_bytes =
      s.octree->vertices.size() * sizeof(Vec3) + s.octree->cells.size() * sizeof(MeshOctreeCell) +
      vertex_block_boxes(s.octree->vertices).size() * sizeof(Aabb);
  for (const std::string name : {"flat", "octree", "octree-strict", "spatial-hash", "lbvh"}) {
    SCOPED_TRACE(name);
    BroadPhaseConfig c = boxes->scene.broadphase;
    c.name = name;
    const std::uint64_t count_only = cuda_device_bytes_needed(static_cast<std::uint64_t>(n), c);
    const std::uint64_t with_boxes = cuda_device_bytes_needed(*boxes, name);
    const std::uint64_t with_spheres = cuda_device_bytes_needed(*spheres, name);
    EXPECT_GE(with_boxes, count_only);
    EXPECT_LT(with_boxes - count_only, 1024u) << "boxes have no octree: a shape record and a theta each";
    // The box model holds one-element minimum buffers of vertices, cells and block boxes.
    EXPECT_GE(with_spheres - with_boxes + sizeof(Vec3) + sizeof(MeshOctreeCell) + sizeof(Aabb), mesh_bytes);
  }
  // The scene says octree-strict at depth auto: the per-body extents are counted.
  BroadPhaseConfig fixed = boxes->scene.broadphase;
  fixed.octree_depth = 2;
  EXPECT_EQ(boxes->scene.broadphase.octree_depth, -1);
  EXPECT_GE(cuda_device_bytes_needed(*boxes, "octree-strict"),
            cuda_device_bytes_needed(static_cast<std::uint64_t>(n), fixed) +
                static_cast<std::uint64_t>(n) * (sizeof(double) + sizeof(std::uint32_t)));
}

// Batched worlds (octocd/worlds.hpp): 65,536 copies of bunny-stack-50 (3,604,480 bodies, the
// benchmark's largest batch, bench/sweeps/worlds.json) fit an H100's 80 GB with room for the
// pair and contact buffers to grow: the engine's estimate before its first step is far below
// it, and under kCudaMaxBodies. Needs the bunny mesh (datasets/fetch.sh).
TEST(CudaFootprint, SixtyFiveThousandWorldsOfBunnyStack50FitAnH100) {
  const char* src = std::getenv("OCTOCD_SOURCE_DIR");
  const std::string dir = std::string(src ? src : ".");
  if (!std::filesystem::exists(dir + "/datasets/cache/bunny.obj") && !std::filesystem::exists(dir + "/datasets/cache/bunny.ply") &&
      !std::filesystem::exists(dir + "/datasets/cache/bunny.off"))
    GTEST_SKIP() << "no bunny mesh in " << dir << "/datasets/cache (run datasets/fetch.sh)";
  const auto single = build_model(load_scene(dir + "/datasets/scenes/bunny-stack-50.json"));
  WorldsSpec spec;
  spec.count = 65536;
  const auto batched = make_worlds_model(single, spec);
  ASSERT_EQ(batched->initial.size(), 65536u * single->initial.size());
  ASSERT_LT(batched->initial.size(), kCudaMaxBodies);
  const std::uint64_t bytes = cuda_device_bytes_needed(*batched, batched->scene.broadphase.name);
  std::cout << "[ info ] 65,536 worlds of bunny-stack-50: " << batched->initial.size() << " bodies, broadphase "
            << batched->scene.broadphase.name << " depth " << batched->scene.broadphase.octree_depth << ", estimate "
            << bytes / 1048576 << " MiB before the first step\n";
  EXPECT_LT(bytes, std::uint64_t{8} << 30) << "an eighth of an H100's memory at most before the buffers grow";
}

// The record ring's pair pool: the engine's pair capacity for every slot when that fits the
// byte budget (what the states and boxes leave), else what fits, never 0; nothing for a
// ring without slots. Numbers worked by hand: 32 slots x 50 bodies x 60 bytes = 96,000 bytes
// of states; 113 bytes a pair.
TEST(RecordRing, PoolIsTheCapacityOfEverySlotWithinTheBudget) {
  using octocd::gpu::record_ring_pairs;
  EXPECT_EQ(record_ring_pairs(400, 32, 50, 60, 113, 64ull << 20), 400u * 32u);
  EXPECT_EQ(record_ring_pairs(400, 32, 50, 60, 113, 96000 + 113 * 1000 + 50), 1000u);
  EXPECT_EQ(record_ring_pairs(400, 32, 50, 60, 113, 96000), 1u) << "no room left: one pair (every step overflows)";
  EXPECT_EQ(record_ring_pairs(400, 32, 50, 60, 113, 1000), 1u) << "states beyond the budget: still one pair";
  EXPECT_EQ(record_ring_pairs(400, 0, 50, 60, 113, 64ull << 20), 1u);
  EXPECT_EQ(record_ring_pairs(1ull << 40, 64, 1, 60, 1, ~0ull), 0xffffffffu) << "clamped to 32 bits";
}

// The host copy's window: which steps it holds (by sequence number), their slots from the
// request's first step, and how far a copy-back reaches: to the batch's last step, at most
// `batch` steps from the one asked for, never past the ring's last slot, never before it.
TEST(RecordRing, WindowHoldsTheCopiedStepsAndCopiesToTheBatchEnd) {
  octocd::gpu::RecordWindow w;
  EXPECT_FALSE(w.holds(0));
  EXPECT_FALSE(w.holds(1));
  w.start(101);  // a request for steps 101 .. 164
  EXPECT_FALSE(w.holds(101));
  EXPECT_EQ(w.slot(101), 0u);
  EXPECT_EQ(w.slot(164), 63u);
  EXPECT_EQ(w.copy_last(101, 164, 64, 64), 164u) << "the whole batch";
  EXPECT_EQ(w.copy_last(101, 164, 32, 64), 132u) << "at most record_batch steps";
  EXPECT_EQ(w.copy_last(140, 164, 64, 32), 140u) << "never before the step asked for";
  EXPECT_EQ(w.copy_last(101, 164, 64, 16), 116u) << "never past the ring's last slot";
  EXPECT_EQ(w.copy_last(101, 90, 64, 64), 101u) << "a batch that ended earlier: the step alone";
  w.copied(101, 132);
  EXPECT_TRUE(w.holds(101));
  EXPECT_TRUE(w.holds(132));
  EXPECT_FALSE(w.holds(133));
  EXPECT_FALSE(w.holds(100));
  w.copied(133, 164);
  EXPECT_FALSE(w.holds(132)) << "a new copy replaces the window";
  EXPECT_TRUE(w.holds(150));
  EXPECT_EQ(w.slot(150), 49u);
  w.start(165);
  EXPECT_FALSE(w.holds(150)) << "a new request holds nothing yet";
  EXPECT_EQ(w.base, 165u);
  w.copied(165, 165);
  w.clear();
  EXPECT_FALSE(w.holds(165));
}

// The next batch, asked for while the host takes this one: the device's 64 statistics slots
// (one per step, by sequence modulo 64) of the steps the host has not taken must survive, so
// from step 101 held with a batch to 132 the next may run 133 .. 164 (31 after its first),
// from 101 to 164 none; the window moves to it when a step of it is asked for, not before.
TEST(RecordRing, NextBatchFitsTheStatisticsSlotsAndMovesTheWindow) {
  using octocd::gpu::RecordWindow;
  unsigned long long room = 99;
  ASSERT_TRUE(RecordWindow::next_batch_room(101, 132, 64, room));
  EXPECT_EQ(room, 31u);
  ASSERT_TRUE(RecordWindow::next_batch_room(101, 101, 64, room));
  EXPECT_EQ(room, 62u) << "102 .. 164";
  EXPECT_FALSE(RecordWindow::next_batch_room(101, 164, 64, room)) << "a batch of 64: no room";
  EXPECT_FALSE(RecordWindow::next_batch_room(101, 170, 64, room));
  RecordWindow w;
  w.start(101);
  w.copied(101, 132);
  w.next_base = 133;
  w.advance(120);
  EXPECT_TRUE(w.holds(120)) << "a step of this batch: the window stays";
  EXPECT_EQ(w.base, 101u);
  w.advance(133);
  EXPECT_EQ(w.base, 133u);
  EXPECT_EQ(w.next_base, 0u);
  EXPECT_FALSE(w.holds(132));
  EXPECT_FALSE(w.holds(133)) << "nothing of the next batch is copied yet";
  EXPECT_EQ(w.slot(140), 7u);
  w.advance(200);
  EXPECT_EQ(w.base, 133u) << "no next batch asked for: the window stays";
}
