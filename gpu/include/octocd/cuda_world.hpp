#pragma once
/// \file cuda_world.hpp
/// The CUDA engine (`cuda`, design.md section 11): the CPU reference step (World::step, design.md section 4) on the
/// device, stage by stage, bit-identical to the CPU engine (same float32 operations in the
/// same order, from the same OCTOCD_HD headers: math.hpp, midphase_hd.hpp).
///
/// Plain C++: including this header needs no CUDA toolkit. `make_cuda_engine` and
/// `cuda_device_status` always exist; in a build without CUDA (OCTOCD_CUDA=OFF, then
/// OCTOCD_HAVE_CUDA is 0) make_cuda_engine throws RuntimeError saying so and the class
/// CudaWorld is not declared.
///
/// Units as everywhere in octocd: metres, seconds, kilograms; state is float32.

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "octocd/cuda_settings.hpp"
#include "octocd/engine.hpp"

#ifndef OCTOCD_HAVE_CUDA
#define OCTOCD_HAVE_CUDA 0
#endif

namespace octocd {

/// The most bodies the cuda engine takes: 2^31 - 1 (it indexes bodies with uint32 and
/// int). Scenes stop far below (limits::kMaxBodies); a Model built another way is checked
/// against this by cuda_device_bytes_needed and the CudaWorld constructor.
constexpr std::uint64_t kCudaMaxBodies = 2147483647;

/// The most bodies for which the cuda engine runs a step as ONE cooperative kernel launch
/// (the small-scene path, gpu/src/small_step.cu) instead of its CUDA graph of per-stage
/// kernels, whose fixed cost (about 80 us per step on an H100) bounds small scenes. The
/// small path's broadphase is the all-pairs `flat` test, whatever broadphase is named (the
/// same pair set by the DeviceBroadPhase contract; O(n^2) tests, cheap below this count),
/// so its `cell_candidates` is n(n-1)/2. It is taken for 1 .. kCudaSmallStepMaxBodies
/// bodies when CudaSettings::small_path is on (the default) and the device can launch
/// cooperative kernels; its stage times come from %globaltimer stamps at the phase ends.
constexpr std::uint64_t kCudaSmallStepMaxBodies = 2048;

/// The broadphases the cuda engine has (`--broadphase` with `--engine cuda`): the rows of
/// octocd/broadphase_table.def with a device side, in its order: flat, octree,
/// octree-strict, spatial-hash, lbvh. Exists in builds without CUDA.
std::vector<std::string> cuda_broadphase_names();

/// The names among cuda_broadphase_names() that only the cuda engine has (rows with no CPU
/// side: neither make_broadphase nor the references know them): lbvh (a Karras 2012 linear BVH, the
/// standard GPU baseline). Exists in builds without CUDA.
std::vector<std::string> cuda_only_broadphase_names();

/// Bytes of device memory the cuda engine allocates for `bodies` bodies before its first
/// step, with broadphase `broadphase.name` (`flat`, `octree`, `octree-strict`,
/// `spatial-hash`, `lbvh`; `broadphase.octree_depth` -1 (auto) adds the strict octree's
/// per-body extents) and no shape data (the packed shape arrays at their minimum of one element;
/// the Model overload adds a model's shapes). Counted: the per-body buffers (state, the
/// state saved before a step, inverse masses, local boxes, shape indices, world AABBs, the
/// broadphase counts and offsets, the contact segments: 116 bytes per body plus 12), the
/// buffers sized by the first pair and work-list capacities (2 n + 64 candidate pairs:
/// keys, pairs, flags, contact terms and records, the body-major contact index; 4 n + 256
/// items in each of two midphase work lists), the step statistics, the device
/// broadphase's reserve() buffers, and CUB's temporary storage as an upper bound. Not
/// counted: the CUDA context, kernels and graph, pinned host memory, and the growth of a
/// step that finds more pairs than the first capacities hold. Linear in `bodies`; the
/// value may exceed the engine's FrameMetrics::memory_bytes after its first step
/// (which has CUB's actual sizes) by the slack of the CUB bounds: under 20 bytes per body
/// plus 1 MiB.
/// Needs no CUDA device and exists in builds without CUDA. Throws InputError for more than
/// kCudaMaxBodies bodies and for a broadphase the device does not have (naming the ones it
/// has).
std::uint64_t cuda_device_bytes_needed(std::uint64_t bodies, const BroadPhaseConfig& broadphase);

/// cuda_device_bytes_needed for `model`'s bodies and shapes (the packed octree vertices,
/// cells and level offsets, one DeviceShape and one theta per shape) with broadphase
/// `broadphase` (as in `--broadphase`; its depth from the scene's broadphase.depth): the
/// estimate the CudaWorld constructor compares with the device's free memory. Bytes.
/// Throws as the overload above.
std::uint64_t cuda_device_bytes_needed(const Model& model, const std::string& broadphase);

/// Creates the CUDA engine for `model` with broadphase `broadphase` (as in
/// `--broadphase`; the device has cuda_broadphase_names(): `flat`, `octree`,
/// `octree-strict`, `spatial-hash` and `lbvh`; the octrees take their depth from the
/// scene's broadphase.depth). The model is shared, not copied.
/// Throws RuntimeError when this octocd was built without CUDA, when no CUDA device is
/// usable (naming the CUDA runtime's reason), when the device has less memory free than
/// cuda_device_bytes_needed(*model, broadphase) (checked before anything is allocated; the
/// message names the scene, the bytes needed, the body count and the bytes free and
/// total; CudaSettings::memory_limit_bytes lowers the free bytes) or when device memory
/// runs out later (naming the buffer and bytes); InputError for a broadphase the device
/// does not have, for more than kCudaMaxBodies bodies and for `settings` out of range
/// (check_cuda_settings).
std::unique_ptr<Engine> make_cuda_engine(std::shared_ptr<const Model> model, const std::string& broadphase,
                                         const CudaSettings& settings = {});

/// One line about the CUDA device: its name, compute capability and memory (e.g.
/// "NVIDIA H100 80GB HBM3 (sm_90, 79.1 GiB)"), or "no CUDA device: <reason from the CUDA
/// runtime>", or "no CUDA device: this octocd was built without CUDA (OCTOCD_CUDA=OFF)".
/// Never throws.
std::string cuda_device_status();

/// True when a CUDA device can be used (cuda_device_status() then names it). Never throws.
bool cuda_device_available();

#if OCTOCD_HAVE_CUDA

/// Seams of CudaWorld for tests only (tests/gpu): no command, scene or Python argument
/// reaches them.
struct CudaTestHooks {
  /// When set, the constructor's memory check takes its result as the free bytes, given
  /// the device's (cudaMemGetInfo): a test plants a shortage on any device with it.
  std::function<std::uint64_t(std::uint64_t free)> free_bytes;
  /// The resident kernel ignores step requests (it still ends on exit), so the host's
  /// timeout (CudaSettings::resident_timeout_ms) fires.
  bool resident_ignores_requests = false;
  /// > 0: the resident kernel ends itself after this many microseconds without a request
  /// instead of 2000 (tests of the idle exit and of the launch count).
  long resident_idle_us = 0;
  /// > 0: the graph path's last midphase expand step runs its leaves itself (the fused
  /// kernel) from this many items on instead of kFuseItemsPerWarp per warp of the grid
  /// (gpu/src/midphase.cuh, fuse_leaves): 1 fuses every step, so tests reach that kernel on
  /// small scenes.
  std::uint32_t fuse_min_items = 0;
  /// > 0: the graph path's witness pass (a thread per pair, before the midphase start)
  /// runs from this many live pairs on instead of kWitnessPassPairsPerWarp per warp of the
  /// start's grid (gpu/src/kernels.hpp): 1 runs it every step.
  std::uint32_t witness_pass_min_pairs = 0;
  /// > 0: the record ring of recorded batches (CudaSettings::record_batch) holds at most
  /// this many bytes instead of 64 MiB, so that a batch's pairs overflow its pool (the step
  /// that does not fit ends the batch and is read from the live buffers).
  std::uint64_t record_ring_max_bytes = 0;
};

/// The CUDA engine. Owns its device buffers (released by the destructor) and a CUDA
/// stream on the current device (device 0 unless the caller selected another with
/// cudaSetDevice); shares the Model it was built from.
///
/// Device layout (structure of arrays): per body x, v (Vec3), w (float), local box
/// (Aabb), world AABB; the per-mesh octrees of all shapes packed once into device arrays
/// (vertices, cells, level offsets, per-shape offsets) and the per-shape theta.
///
/// Step: integrate; world AABBs; broadphase (`flat`: brute force, the device oracle;
/// `octree`: the loose octree of design.md section 5.1 with the cell math of loose_octree.hpp;
/// `octree-strict` and `spatial-hash` with the cell math of strict_octree.hpp and
/// spatial_hash.hpp; `lbvh`: a Karras 2012 linear BVH rebuilt every step, gpu/src/lbvh.hpp;
/// each appends pair keys that are then radix-sorted: the sorted unique set of `flat`); midphase + narrow phase as per-level work lists of box pairs (one warp
/// per pair, per cell pair, per leaf chunk) through the shared OCTOCD_HD functions;
/// response with `response.iterations` passes (per-contact terms, then per body a
/// sequential reduction in (a, b) order over a body-major contact index built by a stable
/// sort: no float atomics); clamp; metrics. No host synchronisation inside a step: every
/// variable-size buffer has a capacity, every producer counts what it found, and a step
/// whose output did not fit is run again from the saved state with larger buffers, so
/// nothing is ever dropped. While the capacities do not change and no frame is being
/// recorded, the step is replayed from a CUDA graph (CudaSettings::graph). Small scenes
/// (kCudaSmallStepMaxBodies, CudaSettings::small_path) run the whole step as one
/// cooperative kernel instead (the same bits: the same per-element device code, pairs in
/// the same order, the same per-body summation order; its grid, one-block response, host
/// wait and fused front are constants beside it in gpu/src/cuda_impl.hpp). Stage times
/// (CudaSettings::stage_times, stage_time_every) are taken on one step in
/// stage_time_every, by CUDA events from a second graph captured with them on the
/// per-stage path, by %globaltimer stamps in the fused kernel; the other steps run untimed
/// and report the last timed step's times; neither changes a bit. On the graph path the
/// last midphase expand step runs its items' leaves itself when it has at least 256 items
/// per warp (the same leaf items, so the same bits and counts).
/// Persistent (resident) kernel: on the small path the kernel is launched once, on a
/// stream of its own, and stays resident (set_persistent(false): a launch per step): it
/// waits on a request word in mapped host memory, runs a step per request (or, after
/// plan_steps, a batch of steps per request) and writes each step's number back, so a step
/// costs no launch. Between requests it touches no state, so
/// state(), set_state() and the recording's copies run beside it (on the engine's
/// stream); reset_capacities(), a buffer regrow (the step's rerun), set_persistent(false)
/// and the destructor end it first (cudaFree waits for every kernel). It ends itself after
/// 2000 us without a request (the next step launches it again), so another engine's work
/// on the device never waits on an idle one for longer. The host waits at most
/// CudaSettings::resident_timeout_ms for a step, then throws RuntimeError (the engine can
/// then only be destroyed).
/// Recorded runs (set_recording) under plan_steps: with CudaSettings::record_batch > 1 the
/// resident kernel runs recorded steps in batches too, up to record_batch steps a request;
/// each step copies its record (the state before and after it, the world AABBs, its pairs,
/// confirmed flags and contact records) into a device ring, which the host copies back to
/// pinned memory once a batch, and step(), contacts(), record() and state() read that copy:
/// the same bits as the step-by-step path (record_batch = 1: a request and a copy per step).
///
/// Errors (all thrown from the constructor or step()): RuntimeError when no device is
/// usable, when the device has less memory free (cudaMemGetInfo) than
/// cuda_device_bytes_needed says the model needs (from the constructor, before anything
/// is allocated: "scene 'S': the cuda engine needs about N bytes (G GiB) of device memory
/// for M bodies before its first step (broadphase 'B'), but the device has F bytes (G GiB)
/// free of T ..."), when a CUDA call fails (naming the call or kernel), when cudaMalloc
/// fails (naming the buffer and the bytes), and when a dynamic body's position or velocity
/// becomes non-finite (the same message as World::step: frame, body, group). InputError
/// for a broadphase the device does not have and for more than kCudaMaxBodies bodies.
/// With CudaSettings::sync_each_launch every launch is followed by a synchronisation and
/// an error check, so an asynchronous fault names its kernel.
///
/// Not thread-safe (like every Engine).
class CudaWorld : public Engine {
 public:
  using TestHooks = CudaTestHooks;

  /// Checks the body count (InputError above kCudaMaxBodies) and that the device has
  /// cuda_device_bytes_needed(*model, broadphase) bytes free (RuntimeError naming the bytes
  /// needed and free otherwise; see the class comment), then uploads the model's initial
  /// state, shapes and octrees. `broadphase` as in `--broadphase` ("flat", "octree",
  /// "octree-strict", "spatial-hash" or "lbvh"). `model` must not be null (InputError); a
  /// rotating scene is refused (InputError naming the key, require_translation_only: the
  /// cuda engine translates only, design.md section 3). `settings` as in CudaSettings (InputError when
  /// out of range, check_cuda_settings); `hooks` for tests only.
  CudaWorld(std::shared_ptr<const Model> model, const std::string& broadphase, const CudaSettings& settings = {},
            const TestHooks& hooks = {});
  ~CudaWorld() override;
  CudaWorld(const CudaWorld&) = delete;
  CudaWorld& operator=(const CudaWorld&) = delete;

  std::string name() const override { return "cuda"; }
  /// The GPU's name, compute capability and memory.
  std::string device() const override;
  std::string broadphase_name() const override;
  const Model& model() const override { return *model_; }
  /// Runs one step (design.md section 4) on the device and returns its metrics (stage times in ms: this
  /// step's when it is timed, else the last timed step's; see the class comment).
  /// Synchronises once, for the metrics (and again only when a buffer had to grow).
  const FrameMetrics& step() override;
  /// Hot state after the last step, downloaded on the first call after each step.
  const BodyState& state() const override;
  const FrameMetrics& last_metrics() const override { return metrics_; }
  std::int64_t frame() const override { return frame_; }
  /// Contacts of the last step's first response pass, in (a, b) order; empty unless
  /// recording (they stay on the device otherwise).
  const std::vector<ContactRecord>& contacts() const override;
  bool octocd_contacts() const override { return true; }
  bool can_record() const override { return true; }
  /// Recording copies the candidate pairs, the confirmed pairs and the contacts back every
  /// step (contacts() reads them; one download each) and keeps x_pre / v_pre on the device
  /// (a device-to-device copy at the step's start); record() copies x_pre, v_pre, the
  /// AABBs, x_post and v_post back on its first call after a step, so a caller that reads
  /// contacts() alone (a trace of contact rows) pays for those alone. Throws RuntimeError
  /// when it changes while the resident kernel runs ahead (plan_steps).
  void set_recording(bool on) override;
  /// On the small path with the resident kernel: a request asks for this step and up to
  /// gpu::kResidentAheadMax (63) more of the `steps` promised, to the next timed step
  /// (stage_time_every), so those run back to back with no host round trip between them
  /// (a batch stops early after a step whose lists overflow or whose body turns
  /// non-finite: the host then reruns it or throws, as without a plan). Each step()
  /// still waits for its own step and returns its metrics. While the device is ahead of
  /// the last step(), state() (a download), set_state(), set_recording(), reset_capacities()
  /// and set_persistent() throw RuntimeError. Elsewhere (other paths, recording,
  /// small_profile) a no-op.
  void plan_steps(std::int64_t steps) override;
  /// The steps of the resident kernel's batch beyond the last step() (0 when none runs
  /// ahead: other paths, no plan, or the batch taken).
  std::int64_t steps_ahead() const override;
  /// The last step's record (recording only): completed from the device on the first
  /// call after a step (see set_recording).
  const FrameRecord& record() const override;

  /// Replaces the hot state (positions, velocities, inverse masses; sizes must equal the
  /// body count, else InputError): tests set up states with it, as with
  /// World::mutable_state.
  void set_state(const BodyState& state) override;

  /// Frees every variable-size device buffer (pairs, contacts, sort index, scratch) and
  /// reallocates it with room for `capacity` elements (>= 1); each grows again when a
  /// counting pass needs more. Tests call it with 1 to exercise every regrow path.
  void reset_capacities(std::size_t capacity = 1);

  /// Bytes of device memory held by this engine's buffers.
  std::uint64_t device_bytes() const;

  /// How a step runs: "small" (one cooperative kernel launch, kCudaSmallStepMaxBodies),
  /// "graph" (the per-stage kernels replayed from a CUDA graph while not recording) or
  /// "launches" (the per-stage kernels launched one by one: CudaSettings::graph off or
  /// sync_each_launch on). Fixed at construction.
  std::string step_path() const;
  /// With CudaSettings::small_profile on the small path: one line of the mean time per
  /// phase of the fused kernel (us, from %globaltimer stamps by thread 0 of block 0 at each
  /// phase's end), the kernel's span, and the host's time from the launch call to seeing the
  /// step done (their difference: launch and wake-up latency), over every step so far;
  /// else "".
  std::string small_profile() const;
  /// True while steps run through the resident small-step kernel (on by default on the
  /// small path; set_persistent).
  bool persistent() const;
  /// Turns the resident kernel on (where persistent() could be true: the small path with the
  /// polled wait; elsewhere a no-op) or off (ending a resident kernel first; the steps then
  /// launch one kernel each). The steps' results do not change. Throws RuntimeError when a
  /// resident kernel does not end (see the class comment).
  void set_persistent(bool on);
  /// Launches of the resident kernel so far: one, plus one per regrow, per
  /// set_persistent(false) / (true) and per idle exit.
  std::uint64_t resident_launches() const;
  /// Requests written to the resident kernel so far: one per step, or one per batch of
  /// steps after plan_steps.
  std::uint64_t resident_requests() const;
  /// With stage times on (CudaSettings::stage_times), every stage but, on the small path,
  /// Aabbs (built in the integration's phase, whose time includes them); off, none.
  bool has_stage(Stage s) const override;
  /// How the stage times were taken (e.g. "stage times: CUDA events between the stages,
  /// sampled 1 step in 64 (steps 1, 65, 129, ...; the others report the last sample)"),
  /// after, on the small path, what it changes in the metrics (broadphase candidates).
  std::string notes() const override;

  struct Impl;  ///< device buffers and the step's host side (gpu/src/cuda_impl.hpp)

 private:
  std::shared_ptr<const Model> model_;
  std::unique_ptr<Impl> impl_;
  FrameMetrics metrics_;
  std::int64_t frame_ = 0;
  bool recording_ = false;
  mutable FrameRecord record_;
  mutable bool record_whole_ = true;  // false: x_pre, v_pre, aabbs, x_post, v_post not yet copied back
  mutable BodyState state_;
  mutable std::int64_t state_frame_ = -1;  // frame whose state state_ holds
};

#endif  // OCTOCD_HAVE_CUDA

}  // namespace octocd
