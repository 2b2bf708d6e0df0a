#pragma once
/// \file engine_registry.hpp
/// The engines octocd has (`cpu`, `cuda`, `bullet`, `mujoco`, `ode`, `dart`) and what each
/// can do: the one place that knows an engine by its name. Callers (CLI, Python, bench)
/// ask an EngineInfo for a capability instead of comparing names (a ctest grep keeps it
/// so). Each engine is one entry of engines/src/engines.cpp: its EngineInfo beside its
/// factory and settings parser (`make_engine`, octocd/engines.hpp), in the library
/// octocd_engines that links every engine's own.

#include <cstddef>
#include <string>
#include <vector>

namespace octocd {

/// What one engine can do. Every field is a fact of the engine, fixed at compile time.
struct EngineInfo {
  std::string name;         ///< as in `--engine`: "cpu", "cuda", "bullet"
  std::string description;  ///< one line for help texts
  /// Its bodies may rotate (a scene with rotation: true, `--rotation`); false: it
  /// translates only and refuses a rotating scene (design.md section 3, require_translation_only).
  bool rotates = false;
  /// It runs the scene's midphase level list (design.md section 5.2); false: `--midphase` is refused.
  bool has_midphase = false;
  /// It runs the broadphase the scene or `--broadphase` names; false: it runs its own
  /// (own_broadphase) and refuses any other name.
  bool uses_scene_broadphase = false;
  /// The broadphase an engine that does not use the scene's runs ("bullet-dbvt"), else "".
  std::string own_broadphase;
  /// That broadphase's class, for messages ("btDbvtBroadphase"), else "".
  std::string own_broadphase_class;
  /// Why an engine without has_midphase has none, for messages, else "".
  std::string no_midphase_reason;
  /// It also has the device-only broadphases (cuda_only_broadphase_names: `lbvh`).
  bool device_broadphases = false;
  /// It runs on a GPU (needs a CUDA build and device).
  bool device = false;
  /// What FrameMetrics::memory_bytes counts, for summaries ("device memory"), or "" when
  /// it is the host's pipeline buffers.
  std::string memory_kind;
  /// It fills a FrameRecord every step of a translation-only scene, so `validate` judges
  /// it in process (cpu, cuda); false: judged as a version 2 external trace when it
  /// records (bullet: hull mode, its default, or rotation; box mode records nothing).
  bool records_every_step = false;
  /// It steps the K copies of `run --worlds K` as one world (octocd/worlds.hpp: cpu,
  /// cuda); false: it steps one scene per run and runs the copies as separate runs
  /// (octocd/world_copies.hpp).
  bool batched_worlds = false;
  /// "" when separate instances of it may step at once on threads of one process; else
  /// why not (library state shared by every instance of the process, unguarded), and
  /// run_copies_separately (octocd/world_copies.hpp) runs its copies one after another.
  std::string not_thread_safe;
  /// The most bodies (walls included) it is known to start and step on this project's
  /// measurements (docs/engines.md, "Set-up of large scenes"), 0 for no limit: make_engine
  /// refuses a larger model at once with `max_bodies_reason`, instead of minutes of set-up
  /// and then a crash or no first frame.
  std::size_t max_bodies = 0;
  /// What was measured above max_bodies, for the refusal, else "".
  std::string max_bodies_reason;
  /// The setting key of its host thread count (cpu: "threads", CpuSettings::threads):
  /// `validate --determinism` runs it at 1 and N threads ("KEY=N") and compares; "" when
  /// it steps on one host thread (or a device), so the thread-count row is n/a.
  std::string threads_setting;
  /// The engine that runs the same pipeline on the other kind of processor ("cuda" for
  /// cpu, "cpu" for cuda), "" for none: `validate --determinism` compares the two bit for bit.
  std::string device_twin;
  /// What it can collide a body as, one per setting it has (the speed-accuracy sweep's
  /// `geometry`): {"mesh"} for octocd's narrow phase on the meshes; {"hull", "box"} for an
  /// engine with a shape setting (bullet: BulletSettings::shape).
  std::vector<std::string> geometries{"mesh"};
  /// The setting key that chooses among `geometries` (bullet: "shape", BulletSettings::
  /// shape), "" when it has one geometry: the speed-accuracy sweep passes "KEY=GEOMETRY".
  std::string geometry_setting;
  /// The setting key of its solver iteration count (bullet: "iterations",
  /// BulletSettings::solver_iterations), "" when it has none: the speed-accuracy sweep's
  /// second axis passes "KEY=N".
  std::string iterations_setting;
  /// A process engine's command (an argument vector, paths resolved; the request's path is
  /// appended when it runs: octocd/process_engines.hpp), read from an engines file; empty
  /// for the built-in engines, which this octocd links.
  std::vector<std::string> command;
};

/// Every engine, built in this octocd or not, in a stable order: cpu, cuda, bullet, mujoco,
/// ode, dart, then the process engines of the engines files (octocd/process_engines.hpp)
/// in their files' order. Throws InputError for a bad engines file (on the first call).
const std::vector<EngineInfo>& engine_infos();

/// The names of the built-in engines (those of engine_infos() without a command), in order.
std::vector<std::string> builtin_engine_names();

/// The names of engine_infos(), in its order.
const std::vector<std::string>& engine_names();

/// The engine `name`, or nullptr for a name no engine has.
const EngineInfo* find_engine_info(const std::string& name);

/// The engine `name`; throws InputError "<where>: unknown engine 'NAME'; allowed: cpu,
/// cuda, bullet, ..." for any other name.
const EngineInfo& engine_info(const std::string& name, const std::string& where);

}  // namespace octocd
