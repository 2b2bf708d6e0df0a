#pragma once
/// \file cuda_settings.hpp
/// The settings of the CUDA engine (`cuda`, design.md section 11): every knob the engine has, in one
/// struct, read once by the CudaWorld constructor. docs/settings.md lists them with the
/// ways to set them: C++ (make_cuda_engine, or `make_engine("cuda", model, {{"cuda", {"graph=false"}}})`),
/// the CLI (`--cuda KEY=VALUE`, repeatable) and Python (`Engine(..., cuda={KEY: VALUE})`).
///
/// Plain C++: including this header needs no CUDA toolkit; the functions exist in builds
/// without CUDA too.

#include <cstdint>
#include <string>
#include <vector>

namespace octocd {

/// The cuda engine's settings. The defaults are what `octocd run --engine cuda` runs.
struct CudaSettings {
  // ---- behaviour ------------------------------------------------------------------------
  /// Midphase early exit: once a pair is confirmed, the rest of its work (its expand and
  /// leaf items, remaining cell tests and vertex tiles) is skipped, and on the per-stage
  /// path a pair confirmed in the last step is first tested at the vertex pair that
  /// confirmed it (its witness),
  /// confirmed with no descent when that pair is still within theta. States, pairs and
  /// contacts are the same bits either way; off, the midphase counts (box tests, box
  /// pairs, vertex tests) are the deterministic work of the level lists, each >= the cpu
  /// engine's. Default true.
  bool midphase_early_exit = true;
  /// The most device memory the engine plans for (unit: bytes; default 0: no limit but
  /// the device's free memory). The constructor refuses a scene whose estimate
  /// (cuda_device_bytes_needed) exceeds min(free, this), with the message that names both.
  std::uint64_t memory_limit_bytes = 0;
  /// How long the host waits for one step of the resident small-step kernel before it
  /// throws RuntimeError (the engine can then only be destroyed) (unit: milliseconds,
  /// 1 .. 86400000; default 60000).
  long resident_timeout_ms = 60000;
  /// Take stage times (FrameMetrics::stage_ms), on one step in stage_time_every. Off, the
  /// stage times stay 0 and CudaWorld::has_stage is false for every stage. The path a step
  /// runs does not depend on it, nor do its results. Default true.
  bool stage_times = true;
  /// Steps per stage-time sample (1 .. 1000000; default 64): steps 1, 1 + k, 1 + 2k, ... are
  /// timed, on the per-stage path by CUDA events between the stages (a second CUDA graph,
  /// captured with them), on the small-scene path by %globaltimer stamps at the fused
  /// kernel's phase ends; every other step runs untimed and reports the last timed step's
  /// stage times, so their mean over a run is the mean over the samples. 1 times every step
  /// (on the per-stage path that costs an event graph every step).
  long stage_time_every = 64;

  // ---- debugging ------------------------------------------------------------------------
  /// Synchronise and check errors after every kernel launch, so that an asynchronous
  /// fault names its kernel; also turns the CUDA graph and the resident kernel off.
  /// Default false.
  bool sync_each_launch = false;
  /// Replay the per-stage kernels from a CUDA graph while the buffer capacities do not
  /// change and no frame is recorded (false: launch them one by one). Default true.
  bool graph = true;
  /// Run scenes of 1 .. kCudaSmallStepMaxBodies bodies as one cooperative kernel per step
  /// (the small-scene path: the same bits); false runs them as the per-stage kernels, as
  /// larger scenes. Default true.
  bool small_path = true;
  /// On the small-scene path: stamp each phase of the fused kernel with %globaltimer and
  /// keep the means (CudaWorld::small_profile). Default false.
  bool small_profile = false;
  /// Recorded runs (Engine::set_recording) on the small-scene path's resident kernel: the
  /// steps a request runs back to back when the caller promised them (Engine::plan_steps),
  /// each copying its record (pairs, confirmed flags, contact records, x_pre, v_pre, AABBs,
  /// the state after it) into a device ring of this many slots, copied back to pinned host
  /// memory in one batch; step(), contacts(), record() and state() then read the host copy.
  /// The records are the same bits either way. 1: every recorded step is its own request and
  /// its own copies (no step ahead). Allowed 1 .. 64; default 32 (against 1 on the H100:
  /// bunny-stack-50 with contact rows 24,706 -> 47,305 steps/s; 16 and 64 not measured): the host asks for the next batch as soon as it has copied one, and the
  /// device's 64 statistics slots leave room for a whole next batch only up to 32 steps.
  long record_batch = 32;
};

/// Throws InputError naming the field, its value and the allowed range when a field of
/// `settings` is out of range (resident_timeout_ms, stage_time_every, record_batch). `where` prefixes the message (e.g.
/// "--cuda").
void check_cuda_settings(const CudaSettings& settings, const std::string& where);

/// The keys set_cuda_setting takes, in the struct's order: the field names.
std::vector<std::string> cuda_setting_names();

/// Sets the field `key` (a name of cuda_setting_names()) of `settings` from text:
/// booleans take true/false/1/0/on/off, integers a decimal number in the field's range.
/// Throws InputError "<where>: ..." naming the key, the value and what is allowed.
void set_cuda_setting(CudaSettings& settings, const std::string& key, const std::string& value,
                      const std::string& where);

/// Applies "KEY=VALUE" items (the CLI's repeated `--cuda KEY=VALUE`) in order with
/// set_cuda_setting. Throws InputError naming `where` and the item for text without '='.
void apply_cuda_settings(CudaSettings& settings, const std::vector<std::string>& items, const std::string& where);

}  // namespace octocd
