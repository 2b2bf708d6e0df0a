// The CUDA engine against the CPU engine (design.md section 11, issue 7): on every shipped scene the
// two engines, both with broadphase `flat`, step side by side and their states must be
// equal bit for bit after every step (state hashes; asserted at least at frames 1, 10,
// 100 and N), with equal pair sets, confirmed-contact sets and contact terms on every
// 10th frame (through record()). On the GPU alone: a rerun gives the same bits, and an
// engine whose buffers all start at capacity 1 (and are shrunk again during the run) gives
// the same results. The device's `octree` broadphase gives the `flat` pair set on every
// scene (the large box scenes included) and the CPU `octree` engine's states. The memory
// check (CudaMemory, issue 8): the host estimate cuda_device_bytes_needed against the
// engine's own count, and a planted shortage (CudaWorld::TestHooks::free_bytes, and
// CudaSettings::memory_limit_bytes through `octocd run|validate --engine cuda --cuda ...`)
// failing construction with exit 1.
//
// Every equality test runs on both step paths of the cuda engine (issue 20): "graph" (the
// per-stage kernels: CudaSettings::small_path off, stage times sampled as by default) and
// "small" (the whole step as one cooperative kernel, stage times off, for scenes of at most
// kCudaSmallStepMaxBodies bodies),
// named by a _graph or _small suffix (e.g. --gtest_filter='*_small*'); CudaSmallStep checks
// the small path against the graph.
//
// Without a usable CUDA device every device test is SKIPPED with the reason
// ("no CUDA device: ..."); the error paths that need no device run everywhere.
//
// Environment: OCTOCD_SOURCE_DIR (scenes and datasets; default: the source tree this was
// built from), OCTOCD_GPU_TEST_FRAMES (frames per scene, default 200), OCTOCD_BIN (the
// `octocd` binary; default: the one built with this test).
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include "kernels.hpp"  // gpu/src: leaf_items, leaf_ranges (host-callable)
#include "octocd/cuda_world.hpp"
#include "octocd/engine.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"
#include "octocd/worlds.hpp"

using namespace octocd;

namespace {

#ifndef OCTOCD_TEST_SOURCE_DIR
#define OCTOCD_TEST_SOURCE_DIR "."
#endif

std::string source_dir() {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return root ? root : OCTOCD_TEST_SOURCE_DIR;
}

int test_frames() {
  const char* s = std::getenv("OCTOCD_GPU_TEST_FRAMES");
  if (!s) return 200;
  const int n = std::atoi(s);
  return n > 0 ? n : 200;
}

/// The issue-8 scale scenes (boxes-uniform-10k..1m, bunny-pile-*): too big for the flat
/// and all-broadphase suites; the CpuVsCudaScale suite covers them with octrees.
bool is_scale_scene(const std::string& name) {
  return name.rfind("bunny-pile-", 0) == 0 ||
         (name.rfind("boxes-uniform-", 0) == 0 && (name.back() == 'k' || name.back() == 'm'));
}

/// The rotating scenes (rot-*, `rotation: true`): only `--engine bullet` runs them (design.md section 13).
bool is_rotating_scene(const std::string& name) { return name.rfind("rot-", 0) == 0; }

/// Every shipped scene except the ones too slow on the CPU side.
std::vector<std::string> shipped_scenes() {
  std::vector<std::string> names;
  const std::filesystem::path dir = std::filesystem::path(source_dir()) / "datasets" / "scenes";
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
    if (e.path().extension() != ".json") continue;
    const std::string name = e.path().stem().string();
    if (name == "boxes-random-10000" || name.rfind("boxes-uniform-", 0) == 0 || is_scale_scene(name) ||
        is_rotating_scene(name))
      continue;
    names.push_back(name);
  }
  std::sort(names.begin(), names.end());
  return names;
}

/// Every shipped scene but the scale scenes (the octree tests also run the large box
/// scenes, for fewer frames).
std::vector<std::string> all_scenes() {
  std::vector<std::string> names;
  const std::filesystem::path dir = std::filesystem::path(source_dir()) / "datasets" / "scenes";
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec))
    if (e.path().extension() == ".json" && !is_scale_scene(e.path().stem().string()) &&
        !is_rotating_scene(e.path().stem().string()))
      names.push_back(e.path().stem().string());
  std::sort(names.begin(), names.end());
  return names;
}

std::string test_name(const ::testing::TestParamInfo<std::string>& info) {
  std::string s = info.param;
  for (char& c : s)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return s;
}

/// The two step paths of the cuda engine every equality test runs (issue 20): "graph"
/// (the per-stage kernels, from a CUDA graph) and "small" (the whole step as one
/// cooperative kernel, for scenes of at most kSmallPathMostBodies bodies; larger scenes
/// stay on the graph).
const std::vector<std::string> kPaths = {"graph", "small"};
constexpr std::size_t kSmallPathMostBodies = kCudaSmallStepMaxBodies;

/// `base` for `path`: "graph" turns the small path off; "small" keeps it and turns the
/// stage times off.
CudaSettings path_settings(const std::string& path, CudaSettings base = {}) {
  base.small_path = path != "graph";
  if (path == "small") base.stage_times = false;
  return base;
}

/// The engine runs the path asked for: "small" where the scene allows it (a device that
/// cannot launch cooperative kernels would fall back: the test then fails, saying so).
void expect_path(const CudaWorld& gpu, const std::string& path, std::size_t bodies, const std::string& what) {
  const bool small = path == "small" && bodies >= 1 && bodies <= kSmallPathMostBodies;
  EXPECT_EQ(gpu.step_path() == "small", small)
      << what << ": asked for the " << path << " path with " << bodies << " bodies, got " << gpu.step_path();
}

using SceneAndPath = std::tuple<std::string, std::string>;

std::string scene_path_name(const ::testing::TestParamInfo<SceneAndPath>& info) {
  std::string s = std::get<0>(info.param) + "_" + std::get<1>(info.param);
  for (char& c : s)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return s;
}

#define REQUIRE_CUDA_DEVICE()                                           \
  do {                                                                  \
    if (!cuda_device_available()) GTEST_SKIP() << cuda_device_status(); \
  } while (0)

/// The scene's model (its own broadphase name is ignored: both engines get `flat`).
std::shared_ptr<const Model> load_model(const std::string& name) {
  const std::string path = source_dir() + "/datasets/scenes/" + name + ".json";
  return build_model(load_scene(path));
}

/// A settings value out of range: constructing a CudaWorld of box-stack with `settings`
/// must throw an InputError whose message holds `says` (checked before the device is
/// looked at, so this runs without one too); an accepted value or a RuntimeError is a
/// failure.
void expect_bad_settings_rejected(const CudaSettings& settings, const std::string& says) {
  const auto model = load_model("box-stack");
  try {
    CudaWorld gpu(model, "flat", settings);
    ADD_FAILURE() << "accepted settings that should say " << says;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
  } catch (const RuntimeError& e) {
    ADD_FAILURE() << "a runtime error, not an input error: " << e.what();
  }
}

std::unique_ptr<World> cpu_flat(const std::shared_ptr<const Model>& model) {
  BroadPhaseConfig cfg = model->scene.broadphase;
  cfg.name = "flat";
  return std::make_unique<World>(model, make_broadphase(cfg, model->scene.domain));
}

std::string bits(float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, 4);
  return fmt::format("{} (0x{:08x})", f, u);
}

bool same_bits(const Vec3& a, const Vec3& b) { return std::memcmp(&a, &b, sizeof(Vec3)) == 0; }

std::string vec(const Vec3& v) { return fmt::format("({}, {}, {})", bits(v.x), bits(v.y), bits(v.z)); }

/// The first body whose x or v bits differ, described; "" when equal.
std::string first_difference(const BodyState& a, const BodyState& b) {
  if (a.size() != b.size()) return fmt::format("body counts differ: {} vs {}", a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (!same_bits(a.x[i], b.x[i])) return fmt::format("body {}: x {} vs {}", i, vec(a.x[i]), vec(b.x[i]));
    if (!same_bits(a.v[i], b.v[i])) return fmt::format("body {}: v {} vs {}", i, vec(a.v[i]), vec(b.v[i]));
  }
  return "";
}

bool same_pairs(const std::vector<Pair>& a, const std::vector<Pair>& b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin());
}

bool same_boxes(const std::vector<Aabb>& a, const std::vector<Aabb>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(Aabb)) == 0);
}

bool same_vecs(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(Vec3)) == 0);
}

/// "" when both contact lists are equal field by field, bit for bit.
std::string contact_difference(const std::vector<ContactRecord>& a, const std::vector<ContactRecord>& b) {
  if (a.size() != b.size()) return fmt::format("contact counts differ: {} vs {}", a.size(), b.size());
  for (std::size_t k = 0; k < a.size(); ++k) {
    const ContactRecord& x = a[k];
    const ContactRecord& y = b[k];
    const bool eq = x.pair == y.pair && same_bits(x.normal, y.normal) &&
                    std::memcmp(&x.depth, &y.depth, 4) == 0 && std::memcmp(&x.jn, &y.jn, 4) == 0 &&
                    std::memcmp(&x.jt, &y.jt, 4) == 0 && x.axis == y.axis && same_bits(x.v_a, y.v_a) &&
                    same_bits(x.v_b, y.v_b) && same_bits(x.dx_a, y.dx_a) && same_bits(x.dx_b, y.dx_b) &&
                    same_bits(x.dv_a, y.dv_a) && same_bits(x.dv_b, y.dv_b);
    if (!eq)
      return fmt::format("contact {} ({}, {}): depth {} vs {}, jn {} vs {}, jt {} vs {}, dv_a {} vs {}", k,
                         x.pair.a, x.pair.b, bits(x.depth), bits(y.depth), bits(x.jn), bits(y.jn), bits(x.jt),
                         bits(y.jt), vec(x.dv_a), vec(y.dv_a));
  }
  return "";
}

/// Compares two engines' records of the same frame (everything the validators read).
void expect_same_record(const FrameRecord& a, const FrameRecord& b, const std::string& what) {
  EXPECT_EQ(a.frame, b.frame) << what;
  EXPECT_TRUE(same_vecs(a.x_pre, b.x_pre)) << what << ": x_pre differs";
  EXPECT_TRUE(same_vecs(a.v_pre, b.v_pre)) << what << ": v_pre differs";
  EXPECT_TRUE(same_boxes(a.aabbs, b.aabbs)) << what << ": world AABBs differ";
  EXPECT_TRUE(same_pairs(a.pairs, b.pairs)) << what << ": candidate pairs differ (" << a.pairs.size() << " vs "
                                            << b.pairs.size() << ")";
  EXPECT_TRUE(same_pairs(a.confirmed, b.confirmed))
      << what << ": confirmed contacts differ (" << a.confirmed.size() << " vs " << b.confirmed.size() << ")";
  const std::string c = contact_difference(a.contacts, b.contacts);
  EXPECT_TRUE(c.empty()) << what << ": " << c;
  EXPECT_TRUE(same_vecs(a.x_post, b.x_post)) << what << ": x_post differs";
  EXPECT_TRUE(same_vecs(a.v_post, b.v_post)) << what << ": v_post differs";
}

/// The midphase counts of two cuda runs on the same states, with the same switches, whose work
/// may differ by the early exit's timing and by the witnesses each kept (midphase.cuh,
/// "Witnesses"): box tests plus vertex tests are zero exactly when the other run's are (a
/// pair that needs a level step either tests its last witness (vertex tests), or runs the
/// start's cell tests, which are never skipped); a step with no box test has no box pair.
void expect_same_zero_counts(const FrameMetrics& a, const FrameMetrics& b, const std::string& what) {
  EXPECT_EQ(a.box_tests + a.vertex_tests == 0, b.box_tests + b.vertex_tests == 0)
      << what << ": box tests " << a.box_tests << " + vertex tests " << a.vertex_tests << " vs " << b.box_tests
      << " + " << b.vertex_tests;
  EXPECT_TRUE(a.box_tests > 0 || a.box_pairs == 0) << what << ": box pairs with no box test";
  EXPECT_TRUE(b.box_tests > 0 || b.box_pairs == 0) << what << ": box pairs with no box test";
}

/// The integer counts of two runs of the cuda engine must match exactly (run to run, and
/// whatever the buffer capacities); the midphase's counts only with no early exit
/// (`no_exit`: CudaSettings::midphase_early_exit off: then they are the lists' whole work
/// and do not depend on timing), else zero together.
void expect_same_counts(const FrameMetrics& a, const FrameMetrics& b, const std::string& what, bool no_exit = false) {
  EXPECT_EQ(a.frame, b.frame) << what;
  EXPECT_EQ(a.cell_candidates, b.cell_candidates) << what;
  EXPECT_EQ(a.aabb_pairs, b.aabb_pairs) << what;
  EXPECT_EQ(a.dynamic_pairs, b.dynamic_pairs) << what;
  if (no_exit) {
    EXPECT_EQ(a.box_tests, b.box_tests) << what;
    EXPECT_EQ(a.box_pairs, b.box_pairs) << what;
    EXPECT_EQ(a.vertex_tests, b.vertex_tests) << what;
  } else {
    expect_same_zero_counts(a, b, what);
  }
  EXPECT_EQ(a.contacts, b.contacts) << what;
}

/// The cpu engine against the cuda engine: the broadphase counts and contacts are equal;
/// the midphase's test counts are the work each engine did: the cpu descends depth first
/// and stops at the first confirmed vertex pair; the cuda engine's level work lists with no
/// early exit (`no_exit`: CudaSettings::midphase_early_exit off) test every candidate, so
/// each of its counts is at least the cpu's, box pairs zero together; with the early exit on
/// they may be fewer (the parallel lists find another first hit, a pair confirmed at its last
/// witness needs no descent), and box pairs are zero when the cpu's are.
/// `same_broadphase_work`: false when the two engines ran different broadphase algorithms
/// (cpu octree vs device octree), whose candidate counts differ by design.
void expect_cpu_cuda_counts(const FrameMetrics& cpu, const FrameMetrics& gpu, const std::string& what,
                            bool same_broadphase_work = true, bool no_exit = false) {
  EXPECT_EQ(cpu.frame, gpu.frame) << what;
  if (same_broadphase_work) {
    EXPECT_EQ(cpu.cell_candidates, gpu.cell_candidates) << what;
  }
  EXPECT_EQ(cpu.aabb_pairs, gpu.aabb_pairs) << what;
  EXPECT_EQ(cpu.contacts, gpu.contacts) << what;
  if (no_exit) {
    EXPECT_GE(gpu.box_tests, cpu.box_tests) << what;
    EXPECT_GE(gpu.box_pairs, cpu.box_pairs) << what;
    EXPECT_GE(gpu.vertex_tests, cpu.vertex_tests) << what;
  }
  if (no_exit) {
    EXPECT_EQ(gpu.box_pairs == 0, cpu.box_pairs == 0) << what;
  } else {
    EXPECT_TRUE(cpu.box_pairs > 0 || gpu.box_pairs == 0) << what << ": box pairs where the cpu has none";
  }
}

/// The engines the midphase tests compare on model m: the CPU engine (octree), a cuda
/// engine with the early exit off (graph path) and the cuda engines with it on, by name
/// (the graph path, and the graph path whose last expand step runs its leaves itself and
/// whose witness pass runs every step: CudaTestHooks::fuse_min_items and
/// witness_pass_min_pairs; a test may add others).
struct ExitEngines {
  static BroadPhaseConfig octree(const Model& m) {
    BroadPhaseConfig cfg = m.scene.broadphase;
    cfg.name = "octree";
    return cfg;
  }
  explicit ExitEngines(const std::shared_ptr<const Model>& m)
      : cpu(m, make_broadphase(octree(*m), m->scene.domain)) {
    CudaSettings no_exit;
    no_exit.midphase_early_exit = false;
    off = std::make_unique<CudaWorld>(m, "octree", path_settings("graph", no_exit));
    on.emplace_back("graph", std::make_unique<CudaWorld>(m, "octree", path_settings("graph")));
    // The last expand step runs its leaves itself, and the witness pass tests the
    // witnesses, every step.
    CudaWorld::TestHooks fuse;
    fuse.fuse_min_items = 1;
    fuse.witness_pass_min_pairs = 1;
    on.emplace_back("graph, fused leaves, witness pass",
                    std::make_unique<CudaWorld>(m, "octree", path_settings("graph"), fuse));
  }
  World cpu;
  std::unique_ptr<CudaWorld> off;
  std::vector<std::pair<std::string, std::unique_ptr<CudaWorld>>> on;
};

bool is_checkpoint(int frame, int frames) { return frame == 1 || frame == 10 || frame == 100 || frame == frames; }

class CpuVsCuda : public ::testing::TestWithParam<SceneAndPath> {};
class CpuVsCudaScale : public ::testing::TestWithParam<std::string> {};
class CudaOctree : public ::testing::TestWithParam<SceneAndPath> {};
class CudaRerun : public ::testing::TestWithParam<SceneAndPath> {};

}  // namespace

TEST(CudaDevice, StatusNamesTheDevice) {
  REQUIRE_CUDA_DEVICE();
  const std::string s = cuda_device_status();
  EXPECT_EQ(s.rfind("no CUDA device", 0), std::string::npos) << s;
  EXPECT_FALSE(s.empty());
}

TEST(CudaDevice, WithoutADeviceMakeEngineSaysWhy) {
  if (cuda_device_available()) GTEST_SKIP() << "a CUDA device is present (" << cuda_device_status() << ")";
  const std::string status = cuda_device_status();
  EXPECT_EQ(status.rfind("no CUDA device: ", 0), 0u) << status;
  const auto model = load_model("free-fall");
  try {
    (void)make_cuda_engine(model, "flat");
    FAIL() << "make_cuda_engine succeeded without a device";
  } catch (const RuntimeError& e) {
    EXPECT_NE(std::string(e.what()).find("no CUDA device: "), std::string::npos) << e.what();
  }
}

TEST(CudaDevice, UnknownBroadphaseIsAnInputError) {  // needs no device: checked first
  const auto model = load_model("free-fall");
  try {
    (void)make_cuda_engine(model, "no-such-broadphase");
    FAIL() << "accepted an unknown broadphase";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("flat"), std::string::npos) << e.what();
  }
}

TEST(CudaDevice, ScenesAreShipped) {
  REQUIRE_CUDA_DEVICE();
  EXPECT_GE(shipped_scenes().size(), 5u) << "scenes under " << source_dir() << "/datasets/scenes";
}

TEST(CudaDevice, EngineSurface) {
  REQUIRE_CUDA_DEVICE();
  const auto model = load_model("box-stack");
  std::unique_ptr<Engine> e = make_cuda_engine(model, "flat");
  EXPECT_EQ(e->name(), "cuda");
  EXPECT_EQ(e->broadphase_name(), "flat");
  EXPECT_TRUE(e->can_record());
  EXPECT_EQ(e->frame(), 0);
  EXPECT_EQ(e->state_hash(), state_hash(model->initial)) << "frame 0 is the model's initial state";
  const FrameMetrics& m = e->step();
  EXPECT_EQ(m.frame, 1);
  EXPECT_EQ(e->frame(), 1);
  EXPECT_GT(m.memory_bytes, 0u);
  for (double ms : m.stage_ms) EXPECT_GE(ms, 0.0);
  EXPECT_TRUE(e->contacts().empty()) << "contacts stay on the device unless recording";
}

/// free-fall with a NaN velocity on its first dynamic body (null when it has none), and the
/// message of the cpu engine's first step on it (World::step's non-finite error).
static std::pair<std::shared_ptr<const Model>, std::string> nan_free_fall() {
  auto model = std::make_shared<Model>(*load_model("free-fall"));
  std::size_t body = 0;
  while (body < model->initial.size() && model->initial.w[body] == 0.0f) ++body;
  if (body == model->initial.size()) return {nullptr, ""};
  model->initial.v[body].y = std::numeric_limits<float>::quiet_NaN();
  std::string cpu_msg;
  try {
    cpu_flat(model)->step();
  } catch (const RuntimeError& e) {
    cpu_msg = e.what();
  }
  return {model, cpu_msg};
}

TEST(CudaDevice, NonFiniteStateGivesTheCpuMessage) {
  REQUIRE_CUDA_DEVICE();
  const auto [model, cpu_msg] = nan_free_fall();
  ASSERT_TRUE(model) << "free-fall has a dynamic body";
  EXPECT_FALSE(cpu_msg.empty());
  for (const std::string& path : kPaths) {
    CudaWorld gpu(model, "flat", path_settings(path));
    expect_path(gpu, path, model->initial.size(), "free-fall");
    std::string gpu_msg;
    try {
      gpu.step();
    } catch (const RuntimeError& e) {
      gpu_msg = e.what();
    }
    EXPECT_EQ(gpu_msg, cpu_msg) << path;
    EXPECT_EQ(gpu.frame(), 0) << path << ": the failed step is not counted";
  }
}

TEST(CudaDevice, OutOfMemoryNamesTheBufferAndBytes) {
  REQUIRE_CUDA_DEVICE();
  const auto model = load_model("box-stack");
  CudaWorld gpu(model, "flat");
  gpu.step();
  try {
    gpu.reset_capacities(std::size_t{1} << 42);  // 16 TiB per uint32 buffer
    FAIL() << "a 16 TiB cudaMalloc succeeded";
  } catch (const RuntimeError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("cudaMalloc of 17592186044416 bytes"), std::string::npos) << msg;
    EXPECT_NE(msg.find("buffer '"), std::string::npos) << msg;
  }
  // The engine recovers: buffers regrow on demand and the run matches a fresh one.
  gpu.reset_capacities(1);
  CudaWorld fresh(model, "flat");
  fresh.step();
  for (int f = 2; f <= 20; ++f) {
    gpu.step();
    fresh.step();
    ASSERT_EQ(gpu.state_hash(), fresh.state_hash()) << "frame " << f;
  }
}

TEST(CudaDevice, SetStateIsUsed) {
  REQUIRE_CUDA_DEVICE();
  const auto model = load_model("bunny-stack-50");
  for (const std::string& path : kPaths) {
    auto cpu = cpu_flat(model);
    CudaWorld gpu(model, "flat", path_settings(path));
    expect_path(gpu, path, model->initial.size(), "bunny-stack-50");
    BodyState s = model->initial;
    for (std::size_t i = 0; i < s.size(); ++i)
      if (s.w[i] > 0.0f) s.v[i] = Vec3{0.25f, -1.5f, 0.125f};
    cpu->mutable_state() = s;
    gpu.set_state(s);
    for (int f = 1; f <= 20; ++f) {
      cpu->step();
      gpu.step();
      ASSERT_EQ(cpu->state_hash(), gpu.state_hash())
          << path << " frame " << f << ": " << first_difference(cpu->state(), gpu.state());
    }
  }
}

// ---- device memory (issue 8, item 7: bad input at scale) --------------------------------

namespace {


/// The message of the RuntimeError that constructing CudaWorld(model, broadphase, settings,
/// hooks) throws, "" when it constructs.
std::string construction_error(const std::shared_ptr<const Model>& model, const std::string& broadphase,
                               const CudaSettings& settings, const CudaWorld::TestHooks& hooks) {
  try {
    CudaWorld gpu(model, broadphase, settings, hooks);
  } catch (const RuntimeError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

// (a) The host estimate against the engine's own count after its first step, on the
// 100k-body scale scene with every device broadphase: at least what the engine holds (the
// estimate may only overshoot, by CUB's bounds) and at most 3 times that.
TEST(CudaMemory, EstimateIsOneToThreeTimesTheEnginesBytesAfterTheFirstStep) {
  REQUIRE_CUDA_DEVICE();
  const auto model = load_model("boxes-uniform-100k");
  for (const std::string bp : {"flat", "octree", "octree-strict", "spatial-hash", "lbvh"}) {
    const std::uint64_t estimate = cuda_device_bytes_needed(*model, bp);
    CudaWorld gpu(model, bp);
    const FrameMetrics m = gpu.step();
    ASSERT_GT(m.memory_bytes, 0u) << bp;
    const double ratio = static_cast<double>(estimate) / static_cast<double>(m.memory_bytes);
    std::cout << "[ info ] boxes-uniform-100k, " << bp << ": estimate " << estimate << " bytes, engine after frame 1 "
              << m.memory_bytes << " bytes (ratio " << ratio << "), " << m.aabb_pairs << " pairs\n";
    EXPECT_GE(ratio, 1.0) << bp << ": the estimate " << estimate << " is below the engine's " << m.memory_bytes;
    EXPECT_LE(ratio, 3.0) << bp << ": the estimate " << estimate << " is over 3 x the engine's " << m.memory_bytes;
  }
}

// (b) With less memory free than the estimate the constructor fails before allocating,
// naming the scene, the bytes needed and free, and the body count; with exactly the
// estimate free it constructs and steps. The free bytes come from the test hook
// TestHooks::free_bytes (a planted shortage: the device itself has plenty), and the same
// shortage from CudaSettings::memory_limit_bytes gives the same message naming the limit.
TEST(CudaMemory, TooLittleFreeMemoryFailsAtConstructionNamingTheBytes) {
  REQUIRE_CUDA_DEVICE();
  for (const std::string name : {"box-stack", "boxes-uniform-100k"}) {
    SCOPED_TRACE(name);
    const auto model = load_model(name);
    const std::string bp = model->scene.broadphase.name;
    const std::uint64_t needed = cuda_device_bytes_needed(*model, bp);
    CudaWorld::TestHooks short_hooks;
    short_hooks.free_bytes = [&](std::uint64_t free) { return std::min<std::uint64_t>(free, needed - 1); };
    {
      const std::string msg = construction_error(model, bp, {}, short_hooks);
      EXPECT_NE(msg.find(fmt::format("scene '{}': the cuda engine needs about {} bytes (", name, needed)),
                std::string::npos)
          << msg;
      EXPECT_NE(msg.find(fmt::format("of device memory for {} bodies before its first step (broadphase '{}')",
                                     model->initial.size(), bp)),
                std::string::npos)
          << msg;
      EXPECT_NE(msg.find(fmt::format("but the device has {} bytes (", needed - 1)), std::string::npos) << msg;
      CudaSettings limited;
      limited.memory_limit_bytes = needed - 1;
      try {
        (void)make_cuda_engine(model, bp, limited);
        ADD_FAILURE() << "make_cuda_engine succeeded with a limit of " << needed - 1 << " bytes";
      } catch (const RuntimeError& e) {
        const std::string lim = e.what();
        EXPECT_NE(lim.find(fmt::format("free (memory_limit_bytes={}) of ", needed - 1)), std::string::npos) << lim;
        EXPECT_EQ(lim.substr(0, lim.find(" free")), msg.substr(0, msg.find(" free")));
      }
    }
    {
      CudaWorld::TestHooks exact;
      exact.free_bytes = [&](std::uint64_t free) { return std::min<std::uint64_t>(free, needed); };
      CudaSettings limited;
      limited.memory_limit_bytes = needed;
      CudaWorld gpu(model, bp, limited, exact);
      EXPECT_EQ(gpu.step().frame, 1) << "exactly the estimate free is enough";
    }
  }
}

#ifdef OCTOCD_TEST_BIN
namespace {

/// Exit status, stdout and stderr of `octocd ARGS` run with `env` (NAME=VALUE words) in
/// front, through the shell; `dir` holds the captured stderr.
struct CliResult {
  int code = -1;
  std::string out, err;
};

CliResult run_octocd(const std::filesystem::path& dir, const std::string& env, const std::vector<std::string>& args) {
  const char* b = std::getenv("OCTOCD_BIN");
  std::string cmd = env + " '" + std::string(b ? b : OCTOCD_TEST_BIN) + "'";
  for (const std::string& a : args) cmd += " '" + a + "'";
  const std::filesystem::path err = dir / "stderr.txt";
  cmd += " 2>'" + err.string() + "'";
  CliResult r;
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  for (std::size_t k; (k = std::fread(buf, 1, sizeof buf, p)) > 0;) r.out.append(buf, k);
  const int status = ::pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream in(err);
  std::ostringstream s;
  s << in.rdbuf();
  r.err = s.str();
  return r;
}

}  // namespace

// (b) through the command line: `run` and `validate` with --engine cuda exit 1 before
// the first step with the one-line message, and leave no trace file behind (the engine is
// built before the trace is opened).
TEST(CudaMemory, CliExitsOneBeforeTheFirstStepNamingTheBytes) {
  REQUIRE_CUDA_DEVICE();
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("octocd-cuda-memory-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string scene = source_dir() + "/datasets/scenes/box-stack.json";
  const auto model = load_model("box-stack");
  const std::uint64_t needed = cuda_device_bytes_needed(*model, model->scene.broadphase.name);
  const std::string limit = "memory_limit_bytes=" + std::to_string(needed - 1);
  const std::string trace = (dir / "t.h5").string();
  const std::vector<std::vector<std::string>> commands = {
      {"run", scene, "--engine", "cuda", "--frames", "5", "--trace", trace, "--quiet", "--cuda", limit},
      {"validate", scene, "--engine", "cuda", "--frames", "5", "--every", "5", "--trace", trace, "--cuda", limit}};
  for (const std::vector<std::string>& args : commands) {
    SCOPED_TRACE(args[0]);
    const CliResult r = run_octocd(dir, "", args);
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_EQ(r.err.rfind("octocd: runtime failure: scene 'box-stack': the cuda engine needs about " +
                              std::to_string(needed) + " bytes",
                          0),
              0u)
        << r.err;
    EXPECT_NE(r.err.find("before its first step"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("but the device has " + std::to_string(needed - 1) + " bytes"), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "one line:\n" << r.err;
    EXPECT_FALSE(std::filesystem::exists(trace)) << "no trace is started before the engine exists";
  }
  // The same command with the estimate free runs.
  std::vector<std::string> enough = commands[0];
  enough.back() = "memory_limit_bytes=" + std::to_string(needed);
  const CliResult ok = run_octocd(dir, "", enough);
  EXPECT_EQ(ok.code, 0) << ok.err;
  EXPECT_TRUE(std::filesystem::exists(trace));
  std::filesystem::remove_all(dir);
}
#endif  // OCTOCD_TEST_BIN

/// Runs CPU (flat) and CUDA side by side on `model` for `frames` frames, asserting equal
/// states after every step and equal records every 10th frame.
void expect_lockstep(const std::shared_ptr<const Model>& model, int frames, const std::string& label,
                     const std::string& path) {
  auto cpu = cpu_flat(model);
  CudaWorld gpu(model, "flat", path_settings(path));
  expect_path(gpu, path, model->initial.size(), label);
  std::uint64_t contacts = 0;
  for (int f = 1; f <= frames; ++f) {
    const bool rec = f % 10 == 0;
    cpu->set_recording(rec);
    gpu.set_recording(rec);
    const FrameMetrics mc = cpu->step();
    const FrameMetrics mg = gpu.step();
    contacts += mc.contacts;
    const std::string what = fmt::format("{} frame {}", label, f);
    ASSERT_EQ(cpu->state_hash(), gpu.state_hash()) << what << ": " << first_difference(cpu->state(), gpu.state());
    expect_cpu_cuda_counts(mc, mg, what);
    if (rec) expect_same_record(cpu->record(), gpu.record(), what);
    if (::testing::Test::HasFailure()) return;
  }
  EXPECT_GT(contacts, 0u) << label << ": the variant must be exercised by contacts";
}

TEST(CudaVariants, RelaxationPassesOverlapModesAndLevelLists) {
  REQUIRE_CUDA_DEVICE();
  const int frames = 300;  // fixed: enough for contacts in every variant, cheap on the device
  for (const char* scene : {"box-stack", "bunny-random-400"}) {
    const auto base = load_model(scene);
    struct Variant {
      const char* label;
      int iterations;
      OverlapMode overlap;
      const char* levels;
    };
    for (const Variant& v : {Variant{"iterations 4", 4, OverlapMode::Separating, nullptr},
                             Variant{"overlap paper, iterations 2", 2, OverlapMode::Paper, nullptr},
                             Variant{"midphase aabb-only", 1, OverlapMode::Separating, "aabb-only"},
                             Variant{"midphase [2]", 1, OverlapMode::Separating, "2"},
                             Variant{"midphase [0,1,2]", 1, OverlapMode::Separating, "0,1,2"}}) {
      auto model = std::make_shared<Model>(*base);
      model->scene.response.iterations = v.iterations;
      model->scene.response.overlap = v.overlap;
      if (v.levels) model->scene.midphase = MidphaseConfig::parse(v.levels);
      for (const std::string& path : kPaths) {
        expect_lockstep(model, frames, fmt::format("{} ({}, {} path)", scene, v.label, path), path);
        if (::testing::Test::HasFailure()) return;
      }
    }
  }
}

// Settings out of range are input errors, before the device is looked at (so this runs
// without a device too); set_cuda_setting parses KEY=VALUE and names what it refuses.
TEST(CudaSettingsCheck, OutOfRangeValuesAreInputErrors) {
  for (const long bad : {0L, -1L, 86400001L}) {
    CudaSettings s;
    s.resident_timeout_ms = bad;
    expect_bad_settings_rejected(s, fmt::format("resident_timeout_ms={} is not allowed; allowed: 1 .. 86400000", bad));
  }
  for (const long bad : {0L, -3L, 1000001L}) {
    CudaSettings t;
    t.stage_time_every = bad;
    expect_bad_settings_rejected(t, fmt::format("stage_time_every={} is not allowed; allowed: 1 .. 1000000", bad));
  }
  for (const long bad : {0L, -2L, 65L}) {
    CudaSettings t;
    t.record_batch = bad;
    expect_bad_settings_rejected(t, fmt::format("record_batch={} is not allowed; allowed: 1 .. 64", bad));
  }
  CudaSettings s;
  EXPECT_EQ(s.record_batch, 32) << "the documented default (docs/settings.md)";
  apply_cuda_settings(s, {"graph=false", "stage_times=0", "midphase_early_exit=off", "memory_limit_bytes=4096",
                          "resident_timeout_ms=300", "sync_each_launch=true", "small_profile=1",
                          "stage_time_every=7", "small_path=off", "record_batch=5"},
                      "--cuda");
  EXPECT_FALSE(s.graph);
  EXPECT_FALSE(s.stage_times);
  EXPECT_EQ(s.stage_time_every, 7);
  EXPECT_FALSE(s.small_path);
  EXPECT_FALSE(s.midphase_early_exit);
  EXPECT_EQ(s.memory_limit_bytes, 4096u);
  EXPECT_EQ(s.resident_timeout_ms, 300);
  EXPECT_TRUE(s.sync_each_launch);
  EXPECT_TRUE(s.small_profile);
  EXPECT_EQ(s.record_batch, 5);
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"graph=yes", "--cuda: graph='yes' is not a switch"},
      {"resident_timeout_ms=0", "--cuda: resident_timeout_ms='0' is not allowed; allowed: an integer 1 .. 86400000"},
      {"memory_limit_bytes=12x", "--cuda: memory_limit_bytes='12x' is not allowed"},
      {"stage_time_every=0", "--cuda: stage_time_every='0' is not allowed; allowed: an integer 1 .. 1000000"},
      {"record_batch=65", "--cuda: record_batch='65' is not allowed; allowed: an integer 1 .. 64"},
      {"small=1", "--cuda: unknown cuda setting 'small'; allowed: midphase_early_exit, "},
      {"graph", "--cuda: 'graph' is not KEY=VALUE"}};
  for (const auto& [item, says] : bad) {
    CudaSettings t;
    try {
      apply_cuda_settings(t, {item}, "--cuda");
      ADD_FAILURE() << "accepted " << item;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
  }
}

// The small path does not change a bit: resident and with a launch per step
// (set_persistent(false)), with the early exit on and off, it gives the graph path's states,
// pairs, contacts, counts (the midphase's exactly with the early exit off, else zero
// together) and metric bits (bunny-stack-50 with its own broadphase `octree`, 300 frames,
// records every 25th). The small engines say what differs: no stage is timed, and their
// broadphase candidates are n(n-1)/2 (the all-pairs test), where the graph's `octree`
// counts its own tests.
TEST(CudaSmallStep, SmallPathGivesTheGraphPathsBits) {
  REQUIRE_CUDA_DEVICE();
  const auto model = load_model("bunny-stack-50");
  const std::uint64_t n = model->initial.size();
  const std::string bp = model->scene.broadphase.name;
  for (const bool no_exit : {false, true}) {
    CudaSettings base;
    base.midphase_early_exit = !no_exit;
    const auto graph = std::make_unique<CudaWorld>(model, bp, path_settings("graph", base));
    const auto dflt = std::make_unique<CudaWorld>(model, bp, path_settings("small", base));
    const auto launches = std::make_unique<CudaWorld>(model, bp, path_settings("small", base));
    launches->set_persistent(false);
    ASSERT_NE(graph->step_path(), "small");
    EXPECT_EQ(graph->notes().find("n(n-1)/2"), std::string::npos) << graph->notes();
    EXPECT_TRUE(graph->has_stage(Stage::Broadphase));
    const std::vector<CudaWorld*> small = {dflt.get(), launches.get()};
    for (CudaWorld* e : small) {
      ASSERT_EQ(e->step_path(), "small");
      EXPECT_FALSE(e->has_stage(Stage::Broadphase));
      EXPECT_NE(e->notes().find("n(n-1)/2"), std::string::npos) << e->notes();
    }
    std::uint64_t contacts = 0, vertex_tests = 0;
    for (int f = 1; f <= 300; ++f) {
      const bool rec = f % 25 == 0;
      graph->set_recording(rec);
      for (CudaWorld* e : small) e->set_recording(rec);
      const FrameMetrics mg = graph->step();
      contacts += mg.contacts;
      vertex_tests += mg.vertex_tests;
      for (CudaWorld* e : small) {
        const FrameMetrics ms = e->step();
        const std::string what = fmt::format("frame {}, small path ({}, early exit {})", f,
                                             e == launches.get() ? "a launch per step" : "resident",
                                             no_exit ? "off" : "on");
        ASSERT_EQ(graph->state_hash(), e->state_hash()) << what << ": " << first_difference(graph->state(), e->state());
        EXPECT_EQ(ms.cell_candidates, n * (n - 1) / 2) << what;
        EXPECT_EQ(mg.aabb_pairs, ms.aabb_pairs) << what;
        EXPECT_EQ(mg.dynamic_pairs, ms.dynamic_pairs) << what;
        if (no_exit) {
          EXPECT_EQ(mg.box_tests, ms.box_tests) << what;
          EXPECT_EQ(mg.box_pairs, ms.box_pairs) << what;
          EXPECT_EQ(mg.vertex_tests, ms.vertex_tests) << what;
        } else {
          expect_same_zero_counts(mg, ms, what);
        }
        EXPECT_EQ(mg.contacts, ms.contacts) << what;
        EXPECT_EQ(mg.kinetic_energy, ms.kinetic_energy) << what << ": the same reduction order";
        EXPECT_EQ(mg.momentum, ms.momentum) << what;
        EXPECT_EQ(mg.penetration_mean, ms.penetration_mean) << what;
        EXPECT_EQ(mg.penetration_max, ms.penetration_max) << what;
        EXPECT_EQ(mg.penetration_share_above_slop, ms.penetration_share_above_slop) << what;
        for (double ms_stage : ms.stage_ms) EXPECT_EQ(ms_stage, 0.0) << what << ": one kernel has no stage times";
        if (rec) expect_same_record(graph->record(), e->record(), what);
        if (::testing::Test::HasFailure()) FAIL() << what << ": stopping at the first frame with a difference";
      }
    }
    EXPECT_GT(contacts, 0u) << "the run must reach contacts";
    EXPECT_GT(vertex_tests, 0u) << "the run must reach the narrow phase";
  }
}

// The fused small step's three broadphases at their body counts' edges, against the cpu every
// step (states, counts; pairs and contact terms every 5th frame): the fused front (n <= 64;
// a 4 x 4 x 4 cluster in which every box overlaps every other, so every row and column is
// full), the shared boxes (65 .. 1024) and the grid's rows from global memory (1025, and
// 2048, the small path's largest: the counts' scan in three tiles of 1024). Cubes
// of half extent 0.1 m on a grid, random velocities, no gravity, no walls; one engine whose
// lists start at capacity 1 (regrow and rerun).
TEST(CudaSmallStep, BroadphaseAtEveryBodyCountEdgeKeepsTheCpuBits) {
  REQUIRE_CUDA_DEVICE();
  for (const int n : {1, 2, 63, 64, 65, 1024, 1025, 2048}) {
    const double spacing = n <= 64 ? 0.05 : 0.15;  // dense: every pair; else the 26 neighbours
    const int side = static_cast<int>(std::ceil(std::cbrt(static_cast<double>(n)) - 1e-9));
    std::string positions;
    for (int i = 0; i < n; ++i) {
      const int ix = i % side, iy = i / side % side, iz = i / (side * side);
      positions += fmt::format("{}[{}, {}, {}]", positions.empty() ? "" : ", ", spacing * ix, spacing * iy, spacing * iz);
    }
    const std::string text = fmt::format(
        R"({{"name": "cubes-{0}", "domain": {{"min": [-4, -4, -4], "max": [6, 6, 6]}}, "dt": 0.001,
            "gravity": [0, 0, 0], "frames": 40, "walls": "none",
            "groups": [{{"name": "cubes", "shape": {{"box": [0.1, 0.1, 0.1]}}, "count": {0}, "mass": 1.0,
                         "positions": [{1}], "velocity": {{"type": "random", "max": 1.0, "seed": 3}}}}]}})",
        n, positions);
    const auto model = build_model(parse_scene(text, fmt::format("cubes-{}", n)));
    ASSERT_EQ(model->initial.size(), static_cast<std::size_t>(n));
    auto cpu = cpu_flat(model);
    CudaWorld gpu(model, "flat", path_settings("small"));
    CudaWorld tiny(model, "flat", path_settings("small"));
    tiny.reset_capacities(1);
    ASSERT_EQ(gpu.step_path(), "small");
    for (int f = 1; f <= 40; ++f) {
      const bool rec = f % 5 == 1;
      cpu->set_recording(rec);
      gpu.set_recording(rec);
      tiny.set_recording(rec);
      const FrameMetrics mc = cpu->step();
      const std::string what = fmt::format("{} cubes, frame {}", n, f);
      if (f == 1 && n <= 64) {
        ASSERT_EQ(mc.aabb_pairs, static_cast<std::uint64_t>(n) * (n - 1) / 2) << what << ": every pair must overlap";
      }
      for (CudaWorld* e : {&gpu, &tiny}) {
        const FrameMetrics mg = e->step();
        ASSERT_EQ(cpu->state_hash(), e->state_hash()) << what << ": " << first_difference(cpu->state(), e->state());
        expect_cpu_cuda_counts(mc, mg, what);
        if (rec) expect_same_record(cpu->record(), e->record(), what);
      }
      if (::testing::Test::HasFailure()) FAIL() << what << ": stopping at the first frame with a difference";
    }
  }
}

// The leaf items of a mesh-mesh cell pair (gpu/src/kernels.hpp, leaf_items / leaf_ranges:
// chunks of B's cell's vertices against parts of A's) cover every pair of the two cells'
// vertices exactly once, each item's ranges non-empty and inside the cells, so the leaves
// test what the CPU's mesh_mesh_leaf tests and the exit-off counts of the items add up to
// the cell pair's (filtered A x filtered B). Host code only: runs without a device.
TEST(CudaMidphase, LeafItemsCoverEveryVertexPairOnce) {
  using octocd::gpu::kLeafAPart;
  using octocd::gpu::kLeafChunk;
  const std::vector<std::uint32_t> counts = {1,  2,  31, 32, 33, kLeafChunk - 1, kLeafChunk, kLeafChunk + 1,
                                             kLeafAPart - 1, kLeafAPart, kLeafAPart + 1, 2 * kLeafAPart + 7,
                                             3 * kLeafChunk, 3 * kLeafAPart + 5};
  for (const std::uint32_t na : counts) {
    for (const std::uint32_t nb : counts) {
      const std::uint32_t items = octocd::gpu::leaf_items(na, nb);
      ASSERT_GE(items, 1u);
      // Each item is the rectangle [a0, a1) x [b0, b1) of vertex pairs, inside the cells: they
      // cover every pair once when no two overlap and their areas add up to na x nb.
      struct Rect {
        std::uint32_t a0, a1, b0, b1;
      };
      std::vector<Rect> rects;
      std::uint64_t area = 0;
      for (std::uint32_t it = 0; it < items; ++it) {
        Rect r{};
        octocd::gpu::leaf_ranges(it, na, nb, r.a0, r.a1, r.b0, r.b1);
        ASSERT_TRUE(r.a0 < r.a1 && r.a1 <= na && r.b0 < r.b1 && r.b1 <= nb)
            << "cells of " << na << " and " << nb << " vertices, item " << it << ": A [" << r.a0 << ", " << r.a1
            << "), B [" << r.b0 << ", " << r.b1 << ")";
        if (items > 1) {
          EXPECT_LE(r.a1 - r.a0, kLeafAPart);
          EXPECT_LE(r.b1 - r.b0, octocd::gpu::leaf_b_chunk(na));
        }
        for (std::size_t q = 0; q < rects.size(); ++q) {
          const Rect& o = rects[q];
          ASSERT_FALSE(r.a0 < o.a1 && o.a0 < r.a1 && r.b0 < o.b1 && o.b0 < r.b1)
              << "cells of " << na << " and " << nb << " vertices: items " << q << " and " << it << " overlap";
        }
        rects.push_back(r);
        area += static_cast<std::uint64_t>(r.a1 - r.a0) * (r.b1 - r.b0);
      }
      ASSERT_EQ(area, static_cast<std::uint64_t>(na) * nb) << "cells of " << na << " and " << nb << " vertices";
    }
  }
  // A cell of up to kLeafAPart vertices is one part: only B is chunked, as before the parts.
  EXPECT_EQ(octocd::gpu::leaf_items(kLeafAPart, 5000), (5000 + kLeafChunk - 1) / kLeafChunk);
  EXPECT_EQ(octocd::gpu::leaf_items(kLeafAPart + 1, kLeafChunk), 2u);
  EXPECT_EQ(octocd::gpu::leaf_items(3 * kLeafAPart, 2 * kLeafChunk), 3u);  // B's chunk 2 x kLeafChunk
  // Up to kLeafWholePairs vertex pairs a cell pair is one item; one pair more, it is split.
  const std::uint32_t b_whole = static_cast<std::uint32_t>(octocd::gpu::kLeafWholePairs / 128);
  EXPECT_EQ(octocd::gpu::leaf_items(128, b_whole), 1u);
  EXPECT_EQ(octocd::gpu::leaf_items(129, b_whole), (b_whole + kLeafChunk - 1) / kLeafChunk);
}

// CudaSettings::midphase_early_exit (issue 20 item 3): skipping the rest of a confirmed
// pair's work changes no bit; it only lowers the midphase counts. On the Table 5 scenes with
// --midphase 1,2 (and bunny-random-400 with 0,1,2) and on a pile, the CPU engine (octree)
// against cuda engines with the early exit off (graph path) and on (graph and small path).
// Every frame: equal state bits; every 25th frame: equal pairs, confirmed contacts and contact terms. Counts: with the exit off each is >= the CPU's (the
// lists' whole work); with it on each is <= the figure with it off on the same state (the
// vertex tests plus at most kWitnessVertexTests witness tests per candidate pair: its last
// witness and the vertex blocks beside it), box tests plus vertex tests
// zero exactly when the box tests with it off are. Over the Table 5 runs together, the engines
// with the exit on must do fewer vertex tests than with the exit off (an exit that is never
// taken fails here).
TEST(CudaMidphase, EarlyExitChangesNoBitAndOnlyLowersTheCounts) {
  REQUIRE_CUDA_DEVICE();
  struct Case {
    const char* scene;
    const char* levels;  // null: the scene's own
    int frames;
    bool table5;  // the exit must save vertex tests over the run
  };
  // Over the Table 5 runs: vertex tests with the exit off, and per exit-on engine (by name).
  std::uint64_t t5_off_vt = 0;
  std::map<std::string, std::uint64_t> t5_vt;  // name -> vertex tests of the exit-on engines
  for (const Case& cs : {Case{"bunny-random-400", "1,2", 200, true}, Case{"armadillo-random-250", "1,2", 150, true},
                         Case{"dragon-random-250", "1,2", 150, true}, Case{"asian-dragon-random-60", "1,2", 150, true},
                         Case{"bunny-random-400", "0,1,2", 100, true}, Case{"bunny-pile-10k", nullptr, 250, false}}) {
    auto model = std::make_shared<Model>(*load_model(cs.scene));
    if (cs.levels) model->scene.midphase = MidphaseConfig::parse(cs.levels);
    const std::shared_ptr<const Model> m = model;
    ExitEngines engines(m);
    World& cpu = engines.cpu;
    const std::unique_ptr<CudaWorld>& off = engines.off;
    auto& on = engines.on;
    if (m->initial.size() <= kSmallPathMostBodies) {
      on.emplace_back("small", std::make_unique<CudaWorld>(m, "octree", path_settings("small")));
      ASSERT_EQ(on.back().second->step_path(), "small") << cs.scene;
    }
    ASSERT_EQ(off->step_path(), "graph");
    std::uint64_t contacts = 0, cpu_vt = 0, off_vt = 0, off_bt = 0;
    std::vector<std::uint64_t> on_vt(on.size(), 0), on_bt(on.size(), 0);
    for (int f = 1; f <= cs.frames; ++f) {
      const bool rec = f % 25 == 0;
      cpu.set_recording(rec);
      off->set_recording(rec);
      for (auto& e : on) e.second->set_recording(rec);
      const FrameMetrics mc = cpu.step();
      const FrameMetrics m0 = off->step();
      const std::string what = fmt::format("{} (levels {}) frame {}", cs.scene, cs.levels ? cs.levels : "own", f);
      contacts += mc.contacts;
      cpu_vt += mc.vertex_tests;
      off_vt += m0.vertex_tests;
      off_bt += m0.box_tests;
      ASSERT_EQ(cpu.state_hash(), off->state_hash())
          << what << " (exit off): " << first_difference(cpu.state(), off->state());
      expect_cpu_cuda_counts(mc, m0, what + " (exit off)", false, true);
      for (std::size_t i = 0; i < on.size(); ++i) {
        CudaWorld& e = *on[i].second;
        const FrameMetrics m1 = e.step();
        const std::string w = what + " (exit on, " + on[i].first + ")";
        on_vt[i] += m1.vertex_tests;
        on_bt[i] += m1.box_tests;
        ASSERT_EQ(cpu.state_hash(), e.state_hash()) << w << ": " << first_difference(cpu.state(), e.state());
        expect_cpu_cuda_counts(mc, m1, w, false, false);
        EXPECT_LE(m1.box_tests, m0.box_tests) << w;
        EXPECT_LE(m1.box_pairs, m0.box_pairs) << w;
        EXPECT_LE(m1.vertex_tests, m0.vertex_tests + octocd::gpu::kWitnessVertexTests * m1.aabb_pairs) << w;
        // With the exit off the start tests cells of every pair that needs a level step; with
        // it on such a pair tests its last witness (vertex tests) or those cells.
        EXPECT_EQ(m1.box_tests + m1.vertex_tests == 0, m0.box_tests == 0) << w;
        EXPECT_EQ(m1.aabb_pairs, m0.aabb_pairs) << w;
        EXPECT_EQ(m1.contacts, m0.contacts) << w;
        if (rec) {
          expect_same_record(cpu.record(), e.record(), w);
          expect_same_record(off->record(), e.record(), w + " vs exit off");
        }
      }
      if (::testing::Test::HasFailure()) FAIL() << what << ": stopping at the first frame with a difference";
    }
    EXPECT_GT(contacts, 0u) << cs.scene << ": the run must reach contacts";
    EXPECT_GT(off_vt, 0u) << cs.scene << ": the run must reach the leaves";
    std::string ratios;
    const auto share = [](std::uint64_t a, std::uint64_t b) {
      return b ? static_cast<double>(a) / static_cast<double>(b) : 0.0;
    };
    for (std::size_t i = 0; i < on.size(); ++i) {
      ratios += fmt::format("; exit on ({}): {} ({:.3f} of off), box tests {:.3f} of off", on[i].first, on_vt[i],
                            share(on_vt[i], off_vt), share(on_bt[i], off_bt));
      if (cs.table5) t5_vt[on[i].first] += on_vt[i];
    }
    if (cs.table5) t5_off_vt += off_vt;
    std::cout << "[ info ] " << cs.scene << " (levels " << (cs.levels ? cs.levels : "own") << "), " << cs.frames
              << " frames equal bit for bit; vertex tests: cpu " << cpu_vt << ", exit off " << off_vt << ratios << "\n";
  }
  ASSERT_EQ(t5_vt.count("graph"), 1u);
  for (const auto& [name, vt] : t5_vt)
    EXPECT_LT(vt, t5_off_vt) << name << ": the early exit saved no vertex test over the Table 5 runs";
}

// The witness cache (midphase.cuh, "Witnesses"; on with the early exit): a pair confirmed in
// one step is first tested at the vertex pair that confirmed it, and confirmed with no
// descent when that pair is still within theta (the per-stage path; the fused small step
// keeps none). On bunny-stack-50 once it rests (frames 201-400) and on the pile
// bunny-pile-10k (frames 101-200): every frame the cuda engine (graph path, exit on) equals
// the CPU bit for bit, and its box tests over the frames are below kWitnessBoxShare of the
// exit-off engine's (the start's cell tests of the persistent contacts are skipped; an early
// exit alone, which never skips a start, stays near 1: 0.98-1.0 on the Table 5 scenes).
TEST(CudaMidphase, WitnessesSkipTheDescentOfPersistentContacts) {
  REQUIRE_CUDA_DEVICE();
  constexpr double kWitnessBoxShare = 0.5;
  struct Case {
    const char* scene;
    int settle, frames;
  };
  for (const Case& cs : {Case{"bunny-stack-50", 200, 200}, Case{"bunny-pile-10k", 100, 100}}) {
    ExitEngines engines(load_model(cs.scene));
    World& cpu = engines.cpu;
    const std::unique_ptr<CudaWorld>& off = engines.off;
    const auto& on = engines.on;
    std::uint64_t off_bt = 0, contacts = 0;
    std::vector<std::uint64_t> on_bt(on.size(), 0);
    for (int f = 1; f <= cs.settle + cs.frames; ++f) {
      const FrameMetrics mc = cpu.step();
      const FrameMetrics m0 = off->step();
      const bool counted = f > cs.settle;
      if (counted) {
        off_bt += m0.box_tests;
        contacts += mc.contacts;
      }
      const std::string what = fmt::format("{} frame {}", cs.scene, f);
      ASSERT_EQ(cpu.state_hash(), off->state_hash()) << what << " (exit off)";
      for (std::size_t i = 0; i < on.size(); ++i) {
        const FrameMetrics m1 = on[i].second->step();
        ASSERT_EQ(cpu.state_hash(), on[i].second->state_hash())
            << what << " (" << on[i].first << "): " << first_difference(cpu.state(), on[i].second->state());
        EXPECT_EQ(m1.contacts, mc.contacts) << what << " (" << on[i].first << ")";
        if (counted) on_bt[i] += m1.box_tests;
      }
    }
    EXPECT_GT(contacts, 0u) << cs.scene << ": the counted frames must hold contacts";
    ASSERT_GT(off_bt, 0u) << cs.scene;
    for (std::size_t i = 0; i < on.size(); ++i) {
      const double share = static_cast<double>(on_bt[i]) / static_cast<double>(off_bt);
      std::cout << "[ info ] " << cs.scene << " (" << on[i].first << "), frames " << cs.settle + 1 << "-"
                << cs.settle + cs.frames << ": box tests " << on_bt[i] << " with witnesses, " << off_bt
                << " with the exit off (" << fmt::format("{:.3f}", share) << ")\n";
      EXPECT_LT(share, kWitnessBoxShare) << cs.scene << " (" << on[i].first << "): the witnesses skipped too few descents";
    }
  }
}

TEST_P(CpuVsCuda, StatesPairsAndContactsEqualBitForBit) {
  REQUIRE_CUDA_DEVICE();
  const std::string name = std::get<0>(GetParam());
  const std::string path = std::get<1>(GetParam());
  const int frames = test_frames();
  const auto model = load_model(name);
  auto cpu = cpu_flat(model);
  CudaWorld gpu(model, "flat", path_settings(path));
  expect_path(gpu, path, model->initial.size(), name);
  ASSERT_EQ(cpu->state_hash(), gpu.state_hash()) << name << ": initial states differ";
  std::uint64_t pairs_seen = 0, contacts_seen = 0;
  double cpu_ms = 0.0, gpu_ms = 0.0;
  std::array<double, static_cast<std::size_t>(Stage::Count)> gpu_stage_ms{};
  for (int f = 1; f <= frames; ++f) {
    const bool rec = f % 10 == 0;
    cpu->set_recording(rec);
    gpu.set_recording(rec);
    const FrameMetrics mc = cpu->step();
    const FrameMetrics mg = gpu.step();
    const std::string what = fmt::format("{} frame {}", name, f);
    pairs_seen += mc.aabb_pairs;
    contacts_seen += mc.contacts;
    if (!rec) {  // timings of plain steps only
      cpu_ms += mc.step_ms;
      gpu_ms += mg.step_ms;
      for (std::size_t s = 0; s < gpu_stage_ms.size(); ++s) gpu_stage_ms[s] += mg.stage_ms[s];
    }
    // Bit-identical after every step; the required checkpoints are named in the message.
    if (cpu->state_hash() != gpu.state_hash()) {
      FAIL() << what << (is_checkpoint(f, frames) ? " (checkpoint)" : "")
             << ": states differ (first at this frame): " << first_difference(cpu->state(), gpu.state());
    }
    expect_cpu_cuda_counts(mc, mg, what);
    EXPECT_NEAR(mg.kinetic_energy, mc.kinetic_energy, 1e-9 * (1.0 + std::fabs(mc.kinetic_energy))) << what;
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(mg.momentum[static_cast<std::size_t>(k)], mc.momentum[static_cast<std::size_t>(k)],
                  1e-9 * (1.0 + std::fabs(mc.momentum[static_cast<std::size_t>(k)])))
          << what;
    EXPECT_NEAR(mg.penetration_mean, mc.penetration_mean, 1e-9 * (1.0 + mc.penetration_mean)) << what;
    EXPECT_EQ(mg.penetration_max, mc.penetration_max) << what;
    EXPECT_EQ(mg.penetration_share_above_slop, mc.penetration_share_above_slop) << what;
    if (rec) {
      expect_same_record(cpu->record(), gpu.record(), what);
      EXPECT_EQ(gpu.contacts().size(), cpu->contacts().size()) << what;
    }
    if (::testing::Test::HasFailure()) FAIL() << what << ": stopping at the first frame with a difference";
  }
  std::string stages;
  for (std::size_t s = 0; s < gpu_stage_ms.size(); ++s)
    stages += fmt::format(" {} {:.3f}", stage_name(static_cast<Stage>(s)), gpu_stage_ms[s] / frames);
  std::cout << "[ info ] " << name << " (" << gpu.step_path() << " path): " << frames << " frames equal bit for bit; " << pairs_seen
            << " candidate pairs and " << contacts_seen << " contacts in total; mean step ms (not recorded) cpu "
            << fmt::format("{:.3f}", cpu_ms / frames) << ", cuda " << fmt::format("{:.3f}", gpu_ms / frames)
            << " (cuda stages ms:" << stages << ")\n";
}

TEST_P(CudaRerun, RerunAndCapacityOneGiveTheSameBits) {
  REQUIRE_CUDA_DEVICE();
  const std::string name = std::get<0>(GetParam());
  const std::string path = std::get<1>(GetParam());
  const int frames = test_frames();
  const auto model = load_model(name);
  const CudaSettings settings = path_settings(path);
  CudaWorld a(model, "flat", settings);
  CudaWorld b(model, "flat", settings);
  CudaWorld tiny(model, "flat", settings);
  expect_path(tiny, path, model->initial.size(), name);
  tiny.reset_capacities(1);
  for (int f = 1; f <= frames; ++f) {
    if (f % 50 == 0) tiny.reset_capacities(1);  // regrow mid-run too
    const bool rec = f % 10 == 0;
    a.set_recording(rec);
    tiny.set_recording(rec);
    const FrameMetrics ma = a.step();
    const FrameMetrics mb = b.step();
    const FrameMetrics mt = tiny.step();
    const std::string what = fmt::format("{} frame {}", name, f);
    ASSERT_EQ(a.state_hash(), b.state_hash()) << what << ": rerun differs: " << first_difference(a.state(), b.state());
    ASSERT_EQ(a.state_hash(), tiny.state_hash())
        << what << ": capacity-1 engine differs: " << first_difference(a.state(), tiny.state());
    expect_same_counts(ma, mb, what + " (rerun)");
    expect_same_counts(ma, mt, what + " (capacity 1)");
    EXPECT_EQ(ma.kinetic_energy, mb.kinetic_energy) << what << ": metrics are reproducible run to run";
    if (rec) expect_same_record(a.record(), tiny.record(), what + " (capacity 1)");
    if (::testing::Test::HasFailure()) FAIL() << what << ": stopping at the first frame with a difference";
  }
}

// The device's loose octree (`octree`) finds exactly the `flat` pair set, so the states
// equal those of the CPU engine with its own `octree` and of the device's `flat`; an
// octree engine whose buffers start at capacity 1 agrees too, and so do the device's
// `octree-strict`, `spatial-hash` and `lbvh` (the last also from capacity 1).
TEST_P(CudaOctree, PairsEqualFlatAndStatesEqualCpuOctree) {
  REQUIRE_CUDA_DEVICE();
  const std::string name = std::get<0>(GetParam());
  const std::string path = std::get<1>(GetParam());
  const bool big = name.rfind("boxes-", 0) == 0;
  const int frames = big ? std::min(test_frames(), 50) : test_frames();
  const auto model = load_model(name);
  const CudaSettings settings = path_settings(path);
  BroadPhaseConfig cfg = model->scene.broadphase;
  cfg.name = "octree";
  World cpu(model, make_broadphase(cfg, model->scene.domain));
  CudaWorld oct(model, "octree", settings);
  CudaWorld flat(model, "flat", settings);
  CudaWorld tiny(model, "octree", settings);
  tiny.reset_capacities(1);
  CudaWorld strict(model, "octree-strict", settings);
  CudaWorld hash(model, "spatial-hash", settings);
  CudaWorld lbvh(model, "lbvh", settings);
  CudaWorld lbvh_tiny(model, "lbvh", settings);  // the capacity-overflow rerun with `lbvh`
  lbvh_tiny.reset_capacities(1);
  for (const CudaWorld* e : {&oct, &flat, &tiny, &strict, &hash, &lbvh, &lbvh_tiny})
    expect_path(*e, path, model->initial.size(), name + " " + e->broadphase_name());
  std::uint64_t pairs_seen = 0;
  for (int f = 1; f <= frames; ++f) {
    const bool rec = f == 1 || f % 10 == 0;
    for (Engine* e : std::initializer_list<Engine*>{&cpu, &oct, &flat, &tiny}) e->set_recording(rec);
    const FrameMetrics mc = cpu.step();
    const FrameMetrics mo = oct.step();
    const FrameMetrics mf = flat.step();
    const FrameMetrics mt = tiny.step();
    const std::string what = fmt::format("{} frame {}", name, f);
    pairs_seen += mo.aabb_pairs;
    ASSERT_EQ(cpu.state_hash(), oct.state_hash()) << what << ": cpu octree vs cuda octree: "
                                                   << first_difference(cpu.state(), oct.state());
    ASSERT_EQ(flat.state_hash(), oct.state_hash()) << what << ": cuda flat vs cuda octree: "
                                                    << first_difference(flat.state(), oct.state());
    ASSERT_EQ(tiny.state_hash(), oct.state_hash()) << what << ": capacity-1 octree differs";
    const FrameMetrics ms = strict.step();
    const FrameMetrics mh = hash.step();
    ASSERT_EQ(strict.state_hash(), oct.state_hash()) << what << ": cuda octree-strict differs";
    ASSERT_EQ(hash.state_hash(), oct.state_hash()) << what << ": cuda spatial-hash differs";
    const FrameMetrics ml = lbvh.step();
    ASSERT_EQ(lbvh.state_hash(), oct.state_hash()) << what << ": cuda lbvh differs";
    const FrameMetrics mlt = lbvh_tiny.step();
    ASSERT_EQ(lbvh_tiny.state_hash(), oct.state_hash()) << what << ": capacity-1 cuda lbvh differs";
    EXPECT_EQ(ml.aabb_pairs, mo.aabb_pairs) << what;
    EXPECT_EQ(mlt.cell_candidates, ml.cell_candidates) << what;
    EXPECT_GE(ml.cell_candidates, ml.aabb_pairs) << what << ": every pair passes an exact test";
    EXPECT_EQ(ms.aabb_pairs, mo.aabb_pairs) << what;
    EXPECT_EQ(mh.aabb_pairs, mo.aabb_pairs) << what;
    EXPECT_EQ(mo.aabb_pairs, mf.aabb_pairs) << what;
    EXPECT_EQ(mo.aabb_pairs, mc.aabb_pairs) << what;
    // `octree`'s pair cache makes its exact tests depend on its history (a rerun advances
    // it, as the CPU octree's cache), not its pairs.
    EXPECT_GE(mt.cell_candidates, mt.aabb_pairs) << what << ": every pair passes an exact test";
    EXPECT_GE(mo.cell_candidates, mo.aabb_pairs) << what << ": every pair passes an exact test";
    if (rec) {
      EXPECT_TRUE(same_pairs(oct.record().pairs, flat.record().pairs)) << what << ": octree pairs != flat pairs";
      EXPECT_TRUE(same_pairs(oct.record().pairs, cpu.record().pairs)) << what << ": cuda octree != cpu octree";
      EXPECT_TRUE(same_pairs(oct.record().pairs, tiny.record().pairs)) << what << ": capacity 1 differs";
      EXPECT_TRUE(same_pairs(oct.record().confirmed, cpu.record().confirmed)) << what;
    }
    if (::testing::Test::HasFailure()) FAIL() << what << ": stopping at the first frame with a difference";
  }
  std::cout << "[ info ] " << name << " (" << oct.step_path() << " path): octree = flat on " << frames << " frames (" << pairs_seen
            << " pairs)\n";
}

// The per-stage path's contact index (response.cu): a body's b-side segment of more than
// gpu::kIndexShortSegment entries is listed and sorted by a block that scans the pairs in
// order (index_long), the shorter ones by the first apply pass. A dynamic plate pressed
// onto a grid of 144 cubes on the floor: it is the last body, so it is the b of every
// (cube, plate) pair and its segment is long; four passes read the sorted segments again.
TEST(CudaContactIndex, LongSegmentsKeepTheCpuBits) {
  REQUIRE_CUDA_DEVICE();
  constexpr int kSide = 12;
  std::string positions;
  for (int i = 0; i < kSide; ++i)
    for (int j = 0; j < kSide; ++j)
      positions += fmt::format("{}[{}, 0.05, {}]", positions.empty() ? "" : ", ", -0.66 + 0.12 * i, -0.66 + 0.12 * j);
  const std::string text = fmt::format(
      R"({{"name": "plate-on-cubes", "domain": {{"min": [-1, 0, -1], "max": [1, 1, 1]}}, "dt": 0.001,
          "frames": 100, "walls": "floor", "response": {{"iterations": 4}},
          "groups": [{{"name": "cubes", "shape": {{"box": [0.05, 0.05, 0.05]}}, "count": {}, "mass": 1.0,
                       "positions": [{}]}},
                     {{"name": "plate", "shape": {{"box": [0.8, 0.02, 0.8]}}, "count": 1, "mass": 5.0,
                       "positions": [[0.0, 0.118, 0.0]]}}]}})",
      kSide * kSide, positions);
  const auto model = build_model(parse_scene(text, "plate-on-cubes"));
  const auto plate = static_cast<std::uint32_t>(model->initial.size() - 1);  // walls first, then the groups
  auto cpu = cpu_flat(model);
  CudaWorld gpu(model, "flat", path_settings("graph"));
  ASSERT_EQ(gpu.step_path(), "graph");
  for (int f = 1; f <= 100; ++f) {
    const bool rec = f % 10 == 1;
    cpu->set_recording(rec);
    gpu.set_recording(rec);
    const FrameMetrics mc = cpu->step();
    const FrameMetrics mg = gpu.step();
    const std::string what = fmt::format("plate-on-cubes frame {}", f);
    if (f == 1) {
      std::size_t as_b = 0;
      for (const ContactRecord& c : cpu->contacts()) as_b += c.pair.b == plate ? 1u : 0u;
      ASSERT_GT(as_b, gpu::kIndexShortSegment) << what << ": the plate's segment must be a long one";
      ASSERT_NE(model->initial.w[plate], 0.0f) << what << ": the plate must be dynamic";
    }
    ASSERT_EQ(cpu->state_hash(), gpu.state_hash()) << what << ": " << first_difference(cpu->state(), gpu.state());
    expect_cpu_cuda_counts(mc, mg, what);
    if (rec) expect_same_record(cpu->record(), gpu.record(), what);
    if (::testing::Test::HasFailure()) FAIL() << what << ": stopping at the first frame with a difference";
  }
}

// Issue 8, item 6: the equality tests at scale. The CPU side runs live with its loose
// octree (flat would be O(n^2) per step); the device `octree` is the one tested equal to
// `flat` above. Every step: equal state bits and counts; every 10th frame: equal pairs,
// confirmed contacts and contact terms. Frames: enough for contacts to pile up (the
// bunnies land after about 100 frames, the layers above them after about 150).
TEST_P(CpuVsCudaScale, StatesPairsAndContactsEqualBitForBit) {
  REQUIRE_CUDA_DEVICE();
  const std::string name = GetParam();
  const int frames = name.rfind("bunny-pile-", 0) == 0 ? 600 : 200;
  const auto model = load_model(name);
  BroadPhaseConfig cfg = model->scene.broadphase;
  cfg.name = "octree";
  World cpu(model, make_broadphase(cfg, model->scene.domain));
  CudaWorld gpu(model, "octree");
  ASSERT_EQ(cpu.state_hash(), gpu.state_hash()) << name << ": initial states differ";
  std::uint64_t pairs_seen = 0, contacts_seen = 0, vertex_tests = 0;
  for (int f = 1; f <= frames; ++f) {
    const bool rec = f % 10 == 0;
    cpu.set_recording(rec);
    gpu.set_recording(rec);
    const FrameMetrics mc = cpu.step();
    const FrameMetrics mg = gpu.step();
    const std::string what = fmt::format("{} frame {}", name, f);
    pairs_seen += mc.aabb_pairs;
    contacts_seen += mc.contacts;
    vertex_tests += mc.vertex_tests;
    ASSERT_EQ(cpu.state_hash(), gpu.state_hash()) << what << ": " << first_difference(cpu.state(), gpu.state());
    expect_cpu_cuda_counts(mc, mg, what, false);
    EXPECT_EQ(mg.penetration_max, mc.penetration_max) << what;
    if (rec) expect_same_record(cpu.record(), gpu.record(), what);
    if (::testing::Test::HasFailure()) FAIL() << what << ": stopping at the first frame with a difference";
  }
  EXPECT_GT(contacts_seen, 0u) << name << ": the run must reach contacts";
  if (name.rfind("bunny-pile-", 0) == 0) {
    EXPECT_GT(vertex_tests, 0u) << name << ": the midphase must reach vertices";
  }
  std::cout << "[ info ] " << name << ": " << frames << " frames equal bit for bit (" << model->initial.size()
            << " bodies); " << pairs_seen << " candidate pairs and " << contacts_seen << " contacts in total\n";
}

INSTANTIATE_TEST_SUITE_P(Scale, CpuVsCudaScale,
                         ::testing::Values("boxes-uniform-10k", "boxes-uniform-100k", "bunny-pile-10k"), test_name);
INSTANTIATE_TEST_SUITE_P(Scenes, CudaOctree, ::testing::Combine(::testing::ValuesIn(all_scenes()), ::testing::ValuesIn(kPaths)),
                         scene_path_name);
GTEST_ALLOW_UNINSTANTIATED_PARAMETERIZED_TEST(CudaOctree);
INSTANTIATE_TEST_SUITE_P(Scenes, CpuVsCuda,
                         ::testing::Combine(::testing::ValuesIn(shipped_scenes()), ::testing::ValuesIn(kPaths)),
                         scene_path_name);
INSTANTIATE_TEST_SUITE_P(Scenes, CudaRerun,
                         ::testing::Combine(::testing::ValuesIn(shipped_scenes()), ::testing::ValuesIn(kPaths)),
                         scene_path_name);
GTEST_ALLOW_UNINSTANTIATED_PARAMETERIZED_TEST(CpuVsCuda);
GTEST_ALLOW_UNINSTANTIATED_PARAMETERIZED_TEST(CudaRerun);

// ---- the resident (persistent) small step (issue 20, item 2) -----------------------------
//
// The small path's kernel stays resident (the default; set_persistent) and steps on
// request. Every test compares with the cpu engine after every step: states bit for bit
// (state() read back while the kernel waits), counts, and on recorded frames the pairs,
// contacts and terms.

namespace {

/// Steps the cpu engine and every engine of `gpus` once, asserts that every state equals the
/// cpu's bit for bit and the counts agree; records on frames divisible by 10.
void step_all_and_compare(World& cpu, const std::vector<CudaWorld*>& gpus, int f, const std::string& label) {
  const bool rec = f % 10 == 0;
  cpu.set_recording(rec);
  const FrameMetrics mc = cpu.step();
  for (CudaWorld* g : gpus) {
    g->set_recording(rec);
    const FrameMetrics mg = g->step();
    const std::string what = fmt::format("{} frame {} ({} path{})", label, f, g->step_path(),
                                         g->persistent() ? ", resident" : "");
    ASSERT_EQ(cpu.state_hash(), g->state_hash()) << what << ": " << first_difference(cpu.state(), g->state());
    expect_cpu_cuda_counts(mc, mg, what);
    if (rec) expect_same_record(cpu.record(), g->record(), what);
    if (::testing::Test::HasFailure()) return;
  }
}

/// A model with the midphase levels the benches use for bunny-stack-50 (1,2).
std::shared_ptr<const Model> with_levels(const std::shared_ptr<const Model>& base, const char* levels) {
  auto m = std::make_shared<Model>(*base);
  m->scene.midphase = MidphaseConfig::parse(levels);
  return m;
}

}  // namespace

/// Test hooks with the resident kernel's idle exit after `idle_us` microseconds.
CudaWorld::TestHooks idle_after(long idle_us) {
  CudaWorld::TestHooks h;
  h.resident_idle_us = idle_us;
  return h;
}

// Many steps through one resident kernel (idle exit far away): the cpu's bits after every
// step with the state read back after every step, recorded frames (the request's flag),
// set_state while the kernel waits (every 97th frame, both engines); the kernel stays
// resident: one launch, plus one per buffer regrow (a regrow ends it: cudaFree).
TEST(CudaPersistent, ManyStepsWithStateReadsAndSetStateEqualTheCpu) {
  REQUIRE_CUDA_DEVICE();
  for (const char* scene : {"bunny-stack-50", "box-stack"}) {
    const auto model = with_levels(load_model(scene), "1,2");
    auto cpu = cpu_flat(model);
    CudaWorld gpu(model, "flat", path_settings("small"), idle_after(600000000L));
    ASSERT_EQ(gpu.step_path(), "small") << scene;
    ASSERT_TRUE(gpu.persistent()) << scene << ": the resident kernel is the small path's default";
    EXPECT_NE(gpu.notes().find("resident kernel"), std::string::npos) << gpu.notes();
    EXPECT_EQ(gpu.resident_launches(), 0u) << "nothing launched before the first step";
    const int frames = 400;
    std::uint64_t grows = 0, last_bytes = 0, contacts = 0;
    for (int f = 1; f <= frames; ++f) {
      if (f % 97 == 0) {
        BodyState s = cpu->state();
        for (std::size_t i = 0; i < s.size(); ++i)
          if (s.w[i] > 0.0f) s.v[i] = s.v[i] * 0.5f + Vec3{0.0f, 0.25f, 0.0f};
        cpu->mutable_state() = s;
        gpu.set_state(s);
      }
      step_all_and_compare(*cpu, {&gpu}, f, scene);
      if (::testing::Test::HasFailure()) FAIL() << scene << " frame " << f;
      contacts += gpu.last_metrics().contacts;
      const std::uint64_t bytes = gpu.last_metrics().memory_bytes;
      if (f > 1 && bytes != last_bytes) ++grows;
      last_bytes = bytes;
    }
    EXPECT_GT(contacts, 0u) << scene;
    EXPECT_GE(gpu.resident_launches(), 1u);
    EXPECT_LE(gpu.resident_launches(), 2 + grows)
        << scene << ": the kernel must stay resident between steps (" << grows << " regrows seen)";
    std::cout << "[ info ] " << scene << ": " << frames << " resident steps equal to the cpu; "
              << gpu.resident_launches() << " launches, " << grows << " regrows\n";
  }
}

// Switching paths in one process, every step against the cpu: a resident engine that is
// switched to a launch per step and back every 25 frames; a resident engine whose buffers
// are shrunk to capacity 1 every 40 frames (regrow: end, rerun, relaunch); a per-step
// engine; the graph path. bunny-random-400 (406 bodies: no fused front) and bunny-stack-50
// (55 bodies: the fused front).
TEST(CudaPersistent, SwitchingPathsAndRegrowsKeepTheCpuBits) {
  REQUIRE_CUDA_DEVICE();
  for (const char* scene : {"bunny-stack-50", "bunny-random-400"}) {
    const auto model = with_levels(load_model(scene), "1,2");
    auto cpu = cpu_flat(model);
    std::unique_ptr<CudaWorld> toggled, tiny, launches, graph;
    toggled = std::make_unique<CudaWorld>(model, "flat", path_settings("small"));
    tiny = std::make_unique<CudaWorld>(model, "flat", path_settings("small"));
    launches = std::make_unique<CudaWorld>(model, "flat", path_settings("small"));
    graph = std::make_unique<CudaWorld>(model, "flat", path_settings("graph"));
    ASSERT_TRUE(toggled->persistent());
    ASSERT_TRUE(tiny->persistent());
    ASSERT_TRUE(launches->persistent());
    launches->set_persistent(false);
    ASSERT_FALSE(launches->persistent());
    ASSERT_EQ(launches->step_path(), "small");
    ASSERT_FALSE(graph->persistent());
    graph->set_persistent(true);  // a no-op off the small path
    ASSERT_FALSE(graph->persistent());
    tiny->reset_capacities(1);
    const int frames = std::string(scene) == "bunny-random-400" ? 150 : 300;
    for (int f = 1; f <= frames; ++f) {
      if (f % 25 == 0) toggled->set_persistent(!toggled->persistent());
      if (f % 40 == 0) tiny->reset_capacities(1);
      step_all_and_compare(*cpu, {toggled.get(), tiny.get(), launches.get(), graph.get()}, f, scene);
      if (::testing::Test::HasFailure()) FAIL() << scene << " frame " << f;
    }
    EXPECT_GT(tiny->resident_launches(), static_cast<std::uint64_t>(frames / 40))
        << "every capacity reset ends the kernel; the next step launches it again";
    EXPECT_GE(toggled->resident_launches(), static_cast<std::uint64_t>(frames / 50));
    EXPECT_EQ(launches->resident_launches(), 0u);
  }
}

// Destroying an engine whose kernel is resident ends the kernel and frees everything: right
// after construction, after steps, after set_persistent(false), several at once; then a new
// resident engine still gives the cpu's bits.
TEST(CudaPersistent, DestroyWhileResident) {
  REQUIRE_CUDA_DEVICE();
  // 200 ms: long enough that the last engine of a round is resident when it is destroyed;
  // short, because two resident kernels need not fit on the device at once (the next
  // engine's launch waits until the previous one has ended itself: on the H100, with
  // 600 s here, the host's 60 s timeout fired instead).
  const CudaWorld::TestHooks idle = idle_after(200000);
  const CudaSettings small = path_settings("small");
  const auto model = with_levels(load_model("bunny-stack-50"), "1,2");
  { CudaWorld unused(model, "flat", small, idle); }
  for (int round = 0; round < 3; ++round) {
    std::vector<std::unique_ptr<CudaWorld>> engines;
    for (int k = 0; k < 3; ++k) {
      engines.push_back(std::make_unique<CudaWorld>(model, "flat", small, idle));
      for (int f = 0; f < 5 + k; ++f) engines.back()->step();
      ASSERT_GT(engines.back()->resident_launches(), 0u);
    }
    if (round == 1) engines[0]->set_persistent(false);
    engines.clear();  // three destructors, two or three with a resident kernel
  }
  auto cpu = cpu_flat(model);
  CudaWorld gpu(model, "flat", small, idle);
  for (int f = 1; f <= 30; ++f) {
    step_all_and_compare(*cpu, {&gpu}, f, "after the destroyed engines");
    if (::testing::Test::HasFailure()) FAIL();
  }
}

// The host's timeout turns a kernel that never finishes a step into a RuntimeError, not a
// deadlock (planted: TestHooks::resident_ignores_requests makes the kernel ignore step requests);
// the engine is then destroyed (the kernel still honours the exit request) and the device
// works: a fresh engine gives the cpu's bits.
TEST(CudaPersistent, HostTimeoutIsAnErrorNotAHang) {
  REQUIRE_CUDA_DEVICE();
  const auto model = with_levels(load_model("bunny-stack-50"), "1,2");
  CudaSettings small = path_settings("small");
  {
    CudaWorld::TestHooks stall;
    stall.resident_ignores_requests = true;
    CudaSettings timeout = small;
    timeout.resident_timeout_ms = 300;
    CudaWorld gpu(model, "flat", timeout, stall);
    ASSERT_TRUE(gpu.persistent());
    try {
      gpu.step();
      ADD_FAILURE() << "a stalled resident kernel's step returned";
    } catch (const RuntimeError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("did not finish step 1 within 300 ms"), std::string::npos) << m;
      EXPECT_NE(m.find("resident_timeout_ms"), std::string::npos) << m;
      EXPECT_NE(m.find("resident_ignores_requests"), std::string::npos) << m;
    }
  }  // destroyed: the exit request ends the kernel
  auto cpu = cpu_flat(model);
  CudaWorld gpu(model, "flat", small);
  for (int f = 1; f <= 20; ++f) {
    step_all_and_compare(*cpu, {&gpu}, f, "after the timeout");
    if (::testing::Test::HasFailure()) FAIL();
  }
}

// The resident kernel ends itself when idle (TestHooks::resident_idle_us = 1: after 1 us
// without a request, so nearly every step finds it gone) and the next step launches it
// again: the same bits as the cpu, whether the kernel took the request or had left.
TEST(CudaPersistent, IdleExitAndRelaunchKeepTheCpuBits) {
  REQUIRE_CUDA_DEVICE();
  const auto model = with_levels(load_model("bunny-stack-50"), "1,2");
  auto cpu = cpu_flat(model);
  CudaWorld gpu(model, "flat", path_settings("small"), idle_after(1));
  ASSERT_TRUE(gpu.persistent());
  for (int f = 1; f <= 200; ++f) {
    step_all_and_compare(*cpu, {&gpu}, f, "idle exits");
    if (::testing::Test::HasFailure()) FAIL();
  }
  EXPECT_GT(gpu.resident_launches(), 1u) << "the cpu's steps between take longer than 1 us: relaunches";
}

// Engine::plan_steps: the resident kernel runs the promised steps in batches (up to 64 a
// request, each ending at the next timed step) and every step() still returns its own
// step's metrics: per frame the cpu's counts, and the kinetic energy of the other planned
// engine (the same kernel's metrics); after the last step the cpu's state. Stage times
// (every 16th step) come from the batches' last steps: held between, new at most samples. An engine shrunk to capacity 1
// regrows inside batches (a batch stops at the step that overflowed; the host reruns it).
// While steps run ahead, state(), set_state(), set_recording(), reset_capacities() and
// set_persistent() are refused; after the last promised step they work again (a recorded
// step from a set state: the cpu's record). The engines run one after the other: two
// resident kernels need not fit on the device at once. bunny-stack-50 (the fused front,
// lean kernel), bunny-random-400 (the lean kernel without the front) and box-stack (the
// one-block response).
TEST(CudaPersistent, PlannedStepsRunAheadWithTheCpuBits) {
  REQUIRE_CUDA_DEVICE();
  for (const char* scene : {"bunny-stack-50", "bunny-random-400", "box-stack"}) {
    const auto model = with_levels(load_model(scene), "1,2");
    const int frames = std::string(scene) == "bunny-random-400" ? 150 : 300;
    auto cpu = cpu_flat(model);
    std::vector<FrameMetrics> ref;
    for (int f = 1; f <= frames; ++f) ref.push_back(cpu->step());
    const std::uint64_t hash = cpu->state_hash();
    const BodyState end = cpu->state();
    cpu->set_recording(true);
    const FrameMetrics after = cpu->step();
    const FrameRecord after_record = cpu->record();
    std::vector<double> energy[2];
    for (int which = 0; which < 2; ++which) {
      const bool planned = which == 0;
      CudaSettings settings = path_settings("small");
      settings.stage_times = planned;
      settings.stage_time_every = 16;
      CudaWorld g(model, "flat", settings, idle_after(600000000L));
      ASSERT_TRUE(g.persistent()) << scene;
      if (!planned) g.reset_capacities(1);
      g.plan_steps(frames);
      std::array<double, static_cast<std::size_t>(Stage::Count)> held{};
      int samples = 0, fresh = 0;
      for (int f = 1; f <= frames; ++f) {
        const FrameMetrics mg = g.step();
        const std::string what = fmt::format("{} frame {} ({})", scene, f, planned ? "planned" : "tiny");
        expect_cpu_cuda_counts(ref[static_cast<std::size_t>(f - 1)], mg, what);
        energy[which].push_back(mg.kinetic_energy);
        if (planned) {
          if ((f - 1) % 16 == 0) {
            if (mg.stage_ms != held) ++fresh;  // %globaltimer ticks 32 ns: two samples may be equal
            ++samples;
          } else {
            EXPECT_EQ(mg.stage_ms, held) << what << ": an untimed step reports the last sample";
          }
          held = mg.stage_ms;
        }
        if (planned && f == 2) {
          EXPECT_THROW((void)g.state(), RuntimeError) << scene << ": the kernel runs ahead of frame 2";
          EXPECT_THROW(g.set_state(end), RuntimeError) << scene;
          EXPECT_THROW(g.set_recording(true), RuntimeError) << scene;
          EXPECT_THROW(g.reset_capacities(1), RuntimeError) << scene;
          EXPECT_THROW(g.set_persistent(false), RuntimeError) << scene;
          try {
            (void)g.state();
          } catch (const RuntimeError& e) {
            EXPECT_NE(std::string(e.what()).find("plan_steps"), std::string::npos) << e.what();
          }
        }
        if (::testing::Test::HasFailure()) FAIL() << what;
      }
      ASSERT_EQ(hash, g.state_hash()) << scene << ": " << first_difference(end, g.state());
      if (planned) {
        EXPECT_EQ(samples, (frames - 1) / 16 + 1) << scene;
        EXPECT_GE(2 * fresh, samples) << scene << ": most timed steps bring a new sample (stale stamps: none)";
        EXPECT_EQ(g.resident_launches(), 1u) << scene;
        // Batches end at each timed step: frame 1 alone, then 16 steps a request.
        EXPECT_EQ(g.resident_requests(), static_cast<std::uint64_t>(1 + (frames - 1 + 15) / 16)) << scene;
        // The promise is kept: state, recording and set_state work again.
        g.set_recording(true);
        g.set_state(end);
        const FrameMetrics mg = g.step();
        expect_cpu_cuda_counts(after, mg, std::string(scene) + " after the plan, recorded");
        expect_same_record(after_record, g.record(), std::string(scene) + " after the plan");
        EXPECT_EQ(cpu->state_hash(), g.state_hash()) << scene;
      } else {
        EXPECT_LT(g.resident_requests(), static_cast<std::uint64_t>(frames / 4))
            << scene << ": stage times off: up to 64 steps a request, plus one per regrow";
        EXPECT_GT(g.resident_launches(), 1u) << scene << ": the regrows end the kernel";
      }
      std::cout << "[ info ] " << scene << ": " << frames << " planned steps equal to the cpu ("
                << (planned ? "stage times every 16" : "from capacity 1") << "): " << g.resident_requests()
                << " requests, " << g.resident_launches() << " launches\n";
    }
    EXPECT_EQ(energy[0], energy[1]) << scene << ": the same steps' metrics from the same kernel";
  }
}

// Engine::steps_ahead: a caller that stops inside a plan (Python's Engine.step(n) on an
// interrupt) ends it with plan_steps(0) and takes the steps the resident kernel already ran
// (steps_ahead() of them, with no new request); the engine is then at a whole step whose
// state is the cpu's of that frame, and state() works again. Without a plan nothing runs
// ahead. bunny-stack-50, stage times off: a batch of up to 64 steps a request.
TEST(CudaPersistent, AnInterruptedPlanTakesTheStepsRunAhead) {
  REQUIRE_CUDA_DEVICE();
  const auto model = with_levels(load_model("bunny-stack-50"), "1,2");
  CudaSettings settings = path_settings("small");
  settings.stage_times = false;
  CudaWorld g(model, "flat", settings, idle_after(600000000L));
  ASSERT_TRUE(g.persistent());
  (void)g.step();
  EXPECT_EQ(g.steps_ahead(), 0) << "no plan: one step a request";
  g.plan_steps(200);
  (void)g.step();
  (void)g.step();
  const std::int64_t ahead = g.steps_ahead();
  EXPECT_GT(ahead, 0) << "the batch of frame 2 runs frames 3 .. 65";
  EXPECT_LE(ahead, 62);
  EXPECT_THROW((void)g.state(), RuntimeError);
  g.plan_steps(0);
  const std::uint64_t requests = g.resident_requests();
  for (std::int64_t i = 0; i < ahead; ++i) (void)g.step();
  EXPECT_EQ(g.steps_ahead(), 0);
  EXPECT_EQ(g.resident_requests(), requests) << "the steps taken were run by the batch already requested";
  const std::int64_t frame = g.frame();
  EXPECT_EQ(frame, 3 + ahead);
  auto cpu = cpu_flat(model);
  for (std::int64_t f = 1; f <= frame; ++f) (void)cpu->step();
  EXPECT_EQ(cpu->state_hash(), g.state_hash()) << first_difference(cpu->state(), g.state());
  (void)g.step();  // no plan: the next step is requested alone
  EXPECT_EQ(g.steps_ahead(), 0);
  EXPECT_EQ(g.resident_requests(), requests + 1);
}

// Recorded runs in batches (CudaSettings::record_batch, issue 67 item 2): with the steps
// promised (plan_steps) a recording engine runs up to record_batch steps a request, each
// step's record copied into the device ring and back to the host a batch at once. After
// every step the record (x_pre, v_pre, AABBs, pairs, confirmed pairs, contacts, x_post,
// v_post), contacts() and the counts equal the cpu engine's bit for bit, and so does
// state() (from the batch's copy, while the kernel runs ahead), for record_batch 1 (the
// step-by-step path: a request per step), 64 and 7, 64 with stage times every 16 steps (a
// batch ends at each timed step), 64 from capacity 1 (reruns end batches), 64 with a
// ring whose pair pool holds about 200 pairs (test hook: steps that overflow it end their
// batch and are read from the live buffers), and 32 with no steps promised (a request a
// step, read from the live buffers). bunny-stack-50 (the fused front), box-stack
// (the one-block response) and bunny-random-400 (the shared boxes). The engines run one
// after the other: two resident kernels need not fit on the device at once.
TEST(CudaPersistent, RecordedBatchesGiveTheStepByStepRecords) {
  REQUIRE_CUDA_DEVICE();
  for (const char* scene : {"bunny-stack-50", "box-stack", "bunny-random-400"}) {
    const auto model = with_levels(load_model(scene), "1,2");
    const int frames = std::string(scene) == "bunny-random-400" ? 120 : 300;
    const std::uint64_t n = model->initial.size();
    auto cpu = cpu_flat(model);
    cpu->set_recording(true);
    std::vector<FrameMetrics> ref_m;
    std::vector<FrameRecord> ref;
    std::vector<std::uint64_t> ref_hash;
    for (int f = 1; f <= frames; ++f) {
      ref_m.push_back(cpu->step());
      ref.push_back(cpu->record());
      ref_hash.push_back(cpu->state_hash());
    }
    struct Variant {
      const char* name;
      long batch;
      bool stage_times;
      bool tiny;
      std::uint64_t pool_pairs;  // 0: the default ring
      bool plan = true;          // plan_steps(frames) before the first step
    };
    const Variant variants[] = {{"record_batch=1", 1, false, false, 0},
                                {"record_batch=64", 64, false, false, 0},
                                {"record_batch=7", 7, false, false, 0},
                                {"record_batch=64, stage times every 16", 64, true, false, 0},
                                {"record_batch=64 from capacity 1", 64, false, true, 0},
                                {"record_batch=64, a pool of 200 pairs", 64, false, false, 200},
                                {"record_batch=32, no steps promised", 32, false, false, 0, false}};
    for (const Variant& v : variants) {
      CudaSettings settings = path_settings("small");
      settings.record_batch = v.batch;
      settings.stage_times = v.stage_times;
      settings.stage_time_every = 16;
      CudaWorld::TestHooks hooks = idle_after(600000000L);
      if (v.pool_pairs > 0)
        hooks.record_ring_max_bytes = static_cast<std::uint64_t>(v.batch) * n * (4 * sizeof(Vec3) + sizeof(Aabb)) +
                                      v.pool_pairs * (sizeof(Pair) + 1 + sizeof(gpu::DeviceContact));
      CudaWorld g(model, "flat", settings, hooks);
      ASSERT_TRUE(g.persistent()) << scene;
      if (v.tiny) g.reset_capacities(1);
      g.set_recording(true);
      if (v.plan) g.plan_steps(frames);
      for (int f = 1; f <= frames; ++f) {
        const std::size_t i = static_cast<std::size_t>(f - 1);
        const FrameMetrics mg = g.step();
        const std::string what = fmt::format("{} frame {} ({})", scene, f, v.name);
        expect_cpu_cuda_counts(ref_m[i], mg, what);
        const std::string c = contact_difference(ref[i].contacts, g.contacts());
        EXPECT_TRUE(c.empty()) << what << ": contacts(): " << c;
        if (f % 3 == 0) {
          EXPECT_EQ(ref_hash[i], g.state_hash()) << what << ": state() after the step";
        }
        expect_same_record(ref[i], g.record(), what);
        if (::testing::Test::HasFailure()) FAIL() << what;
      }
      EXPECT_EQ(ref_hash.back(), g.state_hash()) << scene << " " << v.name;
      const std::uint64_t requests = g.resident_requests();
      if (v.batch == 1 || !v.plan) {
        EXPECT_GE(requests, static_cast<std::uint64_t>(frames)) << scene << " " << v.name << ": a request a step";
      } else if (!v.tiny && v.pool_pairs == 0) {
        EXPECT_LT(requests, static_cast<std::uint64_t>(frames / 4)) << scene << " " << v.name << ": batches";
      }
      std::cout << "[ info ] " << scene << " " << v.name << ": " << frames << " recorded steps equal to the cpu, "
                << requests << " requests, " << g.resident_launches() << " launches\n";
    }
  }
}

// A body that turns non-finite stops the batch at its step: step() throws the cpu's
// message, and so does the next step() (a new request, not a wait for a batch that
// stopped), with stage times off (batches of 64) and a short host timeout.
TEST(CudaPersistent, NonFiniteStopsThePlannedBatch) {
  REQUIRE_CUDA_DEVICE();
  const auto [model, cpu_msg] = nan_free_fall();
  ASSERT_TRUE(model) << "free-fall has a dynamic body";
  ASSERT_FALSE(cpu_msg.empty());
  CudaSettings settings = path_settings("small");
  settings.resident_timeout_ms = 3000;
  CudaWorld gpu(model, "flat", settings);
  ASSERT_TRUE(gpu.persistent());
  gpu.plan_steps(200);
  for (int attempt = 0; attempt < 2; ++attempt) {
    std::string gpu_msg;
    try {
      gpu.step();
    } catch (const RuntimeError& e) {
      gpu_msg = e.what();
    }
    EXPECT_EQ(gpu_msg, cpu_msg) << "attempt " << attempt;
    EXPECT_EQ(gpu.frame(), 0);
  }
  EXPECT_EQ(gpu.resident_requests(), 2u);
}

// Stage times cost the step nothing and change no bit (issue 33 item 1): by default one step
// in CudaSettings::stage_time_every is timed (%globaltimer stamps of the fused kernel on the
// small path, the graph captured with events on the per-stage path) and the others report
// that step's times. Every engine steps beside the cpu engine with its bits after every
// step: the default (small path, resident), stamps on every step, a launch per step, the
// per-stage path from its graphs sampled every 3rd and on every step, launch by launch
// every 5th, and stage times off.
TEST(CudaStageTimes, SampledStageTimesKeepTheCpuBits) {
  REQUIRE_CUDA_DEVICE();
  const auto model = with_levels(load_model("bunny-stack-50"), "1,2");
  auto cpu = cpu_flat(model);
  struct Spec {
    const char* label;
    CudaSettings settings;
    bool resident;
    long every;  // 0: stage times off
  };
  auto with = [](bool small_path, bool graph, bool times, long every) {
    CudaSettings s;
    s.small_path = small_path;
    s.graph = graph;
    s.stage_times = times;
    s.stage_time_every = every;
    return s;
  };
  const std::vector<Spec> specs = {{"default", CudaSettings{}, true, 64},
                                     {"small, every step", with(true, true, true, 1), true, 1},
                                     {"small, a launch per step", CudaSettings{}, false, 64},
                                     {"graph, every 3rd", with(false, true, true, 3), false, 3},
                                     {"graph, every step", with(false, true, true, 1), false, 1},
                                     {"launches, every 5th", with(false, false, true, 5), false, 5},
                                     {"small, off", with(true, true, false, 64), true, 0}};
  std::vector<std::unique_ptr<CudaWorld>> engines;
  std::vector<CudaWorld*> all;
  for (const Spec& e : specs) {
    engines.push_back(std::make_unique<CudaWorld>(model, "flat", e.settings));
    engines.back()->set_persistent(e.resident);
    all.push_back(engines.back().get());
  }
  EXPECT_EQ(CudaSettings{}.stage_time_every, 64);
  EXPECT_TRUE(CudaSettings{}.stage_times);
  EXPECT_EQ(all[0]->step_path(), "small") << "the default runs the fused kernel, stage times on";
  EXPECT_TRUE(all[0]->persistent());
  EXPECT_NE(all[0]->notes().find("sampled 1 step in 64 (steps 1, 65, 129, ...;"), std::string::npos)
      << all[0]->notes();
  EXPECT_NE(all[1]->notes().find("stamps at the fused kernel's phase ends, on every step"), std::string::npos)
      << all[1]->notes();
  EXPECT_EQ(all[3]->step_path(), "graph");
  EXPECT_EQ(all[3]->notes(), "stage times: CUDA events between the stages, sampled 1 step in 3 (steps 1, 4, 7, "
                             "...; the others report the last sample)");
  EXPECT_EQ(all[5]->step_path(), "launches");
  EXPECT_NE(all[6]->notes().find("stage times: off"), std::string::npos) << all[6]->notes();
  for (std::size_t i = 0; i < specs.size(); ++i) {
    for (int s = 0; s < static_cast<int>(Stage::Count); ++s) {
      const auto st = static_cast<Stage>(s);
      const bool expected = specs[i].every > 0 && !(all[i]->step_path() == "small" && st == Stage::Aabbs);
      EXPECT_EQ(all[i]->has_stage(st), expected) << specs[i].label << ": " << stage_name(st);
    }
  }
  std::vector<FrameMetrics> last(specs.size());
  std::vector<double> timed_sum(specs.size(), 0.0);
  for (int f = 1; f <= 140; ++f) {
    step_all_and_compare(*cpu, all, f, "stage times");
    if (::testing::Test::HasFailure()) FAIL() << "frame " << f;
    for (std::size_t i = 0; i < specs.size(); ++i) {
      const FrameMetrics& m = all[i]->last_metrics();
      const std::string what = fmt::format("{}, frame {}", specs[i].label, f);
      double sum = 0.0;
      for (double ms : m.stage_ms) {
        EXPECT_GE(ms, 0.0) << what;
        sum += ms;
      }
      if (specs[i].every == 0) {
        EXPECT_EQ(sum, 0.0) << what << ": stage times off";
      } else if ((f - 1) % specs[i].every == 0) {
        EXPECT_GT(sum, 0.0) << what << ": a timed step";
        // The stages ran inside the step the host waited for.
        EXPECT_LE(sum, m.step_ms + 0.01) << what;
        timed_sum[i] += sum;
      } else {
        EXPECT_EQ(m.stage_ms, last[i].stage_ms) << what << ": an untimed step reports the last sample";
      }
      last[i] = m;
    }
  }
  for (std::size_t i = 0; i + 1 < specs.size(); ++i) EXPECT_GT(timed_sum[i], 0.0) << specs[i].label;
}

// Batched worlds (octocd/worlds.hpp, `run --worlds`): 64 copies of bunny-stack-50 in one
// world (3,520 bodies: the graph path), copies 1..63 perturbed by up to 0.1 mm so no two
// copies are alike, stepped by both engines with the scene's own broadphase (octree,
// deepened for the grid) as `octocd run --worlds 64 --world-perturb 1e-4` does: states equal
// bit for bit after every step, contacts found, and every copy in its cell at the end.
// `hooks`: the cuda engine's test hooks; `what`: its name in the messages.
static void expect_sixty_four_worlds_equal_the_cpu(const CudaWorld::TestHooks& hooks, const std::string& what_engine) {
  WorldsSpec spec;
  spec.count = 64;
  spec.perturb = 1e-4;
  spec.seed = 3;
  const auto single = load_model("bunny-stack-50");
  const WorldsLayout layout = worlds_layout(*single, spec);
  const auto model = make_worlds_model(*single, layout.offsets, spec);
  ASSERT_EQ(model->initial.size(), 64 * single->initial.size());
  World cpu(model, make_broadphase(model->scene.broadphase, model->scene.domain));
  CudaWorld gpu(model, model->scene.broadphase.name, CudaSettings{}, hooks);
  ASSERT_EQ(cpu.state_hash(), gpu.state_hash()) << "initial states differ";
  const int frames = std::max(test_frames(), 400);  // the bunnies land from frame ~150 on
  std::uint64_t contacts = 0;
  for (int f = 1; f <= frames; ++f) {
    const FrameMetrics mc = cpu.step();
    const FrameMetrics mg = gpu.step();
    contacts += mc.contacts;
    const std::string what = fmt::format("bunny-stack-50 x64 worlds ({}) frame {}", what_engine, f);
    if (cpu.state_hash() != gpu.state_hash())
      FAIL() << what << ": states differ (first at this frame): " << first_difference(cpu.state(), gpu.state());
    expect_cpu_cuda_counts(mc, mg, what, /*same_broadphase_work=*/false);  // cpu and device octrees
    if (::testing::Test::HasFailure()) FAIL() << what << ": stopping at the first frame with a difference";
  }
  EXPECT_GT(contacts, 0u) << "the copies' bunnies never touched: the run compared free fall only";
  EXPECT_TRUE(worlds_escaped(*model, layout, spec.margin, gpu.state()).empty());
  std::cout << "[ info ] bunny-stack-50 x64 worlds (" << what_engine << ", " << gpu.step_path() << " path): " << frames
            << " frames equal bit for bit, " << contacts << " contacts in total\n";
}

TEST(CudaWorlds, SixtyFourCopiesOfBunnyStack50EqualTheCpuBitForBit) {
  REQUIRE_CUDA_DEVICE();
  expect_sixty_four_worlds_equal_the_cpu({}, "cuda");
}

// The same with the witness pass on every step (CudaTestHooks::witness_pass_min_pairs 1):
// it decides the copies' static-static wall pairs itself, and mid_start runs only the
// pairs it left open (midphase.cuh, mid_start_items). On its own the pass runs from 4
// pairs per warp of mid_start's grid (16,896 pairs on an H100's 132 SMs; 65,536 copies have
// 505,856 wall pairs), which 64 copies never reach.
TEST(CudaWorlds, SixtyFourCopiesWithTheWitnessPassEveryStepEqualTheCpuBitForBit) {
  REQUIRE_CUDA_DEVICE();
  CudaWorld::TestHooks hooks;
  hooks.witness_pass_min_pairs = 1;
  expect_sixty_four_worlds_equal_the_cpu(hooks, "cuda, witness pass every step");
}
