// The engine registry (engines/include/octocd/engine_registry.hpp, engines/include/octocd/
// engines.hpp) against the engines it builds: every capability an EngineInfo states is
// checked on the engine itself (broadphase and midphase it runs, recording, rotation), on
// box-stack; apply_engine_options refuses what an engine cannot run, with the caller's
// spelling (CLI flags or Python keywords); traces of octocd's own engines are the ones
// judged with its contact conventions. The cuda engine is checked where a device is.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <string>

#include <fmt/format.h>

#include "octocd/engine_registry.hpp"
#include "octocd/engines.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/trace.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_engine_registry {

using namespace octocd;

namespace {

std::string source_dir() {
  const char* s = std::getenv("OCTOCD_SOURCE_DIR");
  return s ? s : ".";
}

Scene box_stack() { return load_scene(source_dir() + "/datasets/scenes/box-stack.json"); }

/// The InputError message of apply_engine_options, "" when it accepts.
std::string refusal(const std::string& engine, const EngineOptions& o, const ArgumentNames& names) {
  Scene scene = box_stack();
  try {
    apply_engine_options(scene, engine_info(engine, "engine"), o, names);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

/// The adapters the build registered (octocd_register_engine: OCTOCD_REGISTERED_ADAPTERS,
/// tests/CMakeLists.txt), in registration order.
std::vector<std::string> registered_adapters() {
  std::vector<std::string> names;
  std::string list = OCTOCD_REGISTERED_ADAPTERS;
  for (std::size_t at = 0; at < list.size();) {
    const std::size_t comma = std::min(list.find(',', at), list.size());
    names.push_back(list.substr(at, comma - at));
    at = comma + 1;
  }
  return names;
}

TEST(EngineRegistry, EveryRegisteredAdapterIsABuiltEngine) {
  // octocd's own engines first, then the adapters: each name once, none with a command.
  const std::vector<std::string> builtin = builtin_engine_names();
  ASSERT_GE(builtin.size(), 3u);
  EXPECT_EQ(builtin[0], "cpu");
  EXPECT_EQ(builtin[1], "cuda");
  for (std::size_t i = 0; i < builtin.size(); ++i)
    EXPECT_EQ(std::count(builtin.begin(), builtin.end(), builtin[i]), 1) << builtin[i];
  // Every adapter registered by the build (bullet always: its package is required) is in
  // the registry's table and built; the registry's table has no adapter the build lacks
  // but it says so (engine_unavailable: "not built").
  const std::vector<std::string> adapters = registered_adapters();
  ASSERT_NE(std::find(adapters.begin(), adapters.end(), "bullet"), adapters.end()) << OCTOCD_REGISTERED_ADAPTERS;
  const std::vector<std::string> built = built_engine_names();
  for (const std::string& a : adapters) {
    EXPECT_NE(std::find(builtin.begin(), builtin.end(), a), builtin.end()) << a << " is not in engines.cpp's table";
    EXPECT_NE(std::find(built.begin(), built.end(), a), built.end()) << a << " registered but not built";
  }
  for (std::size_t i = 2; i < builtin.size(); ++i) {
    const bool registered = std::find(adapters.begin(), adapters.end(), builtin[i]) != adapters.end();
    const EngineInfo& info = engine_info(builtin[i], "engine");
    EXPECT_EQ(engine_built(info), registered) << builtin[i];
    if (!registered) {
      EXPECT_NE(engine_unavailable(info).find("not built"), std::string::npos) << engine_unavailable(info);
    }
  }
}

TEST(EngineRegistry, CapabilitiesAreWhatTheEnginesDo) {
  const std::size_t builtin_count = builtin_engine_names().size();
  // Then the process engines of the engines files (the build tree's: rapier, jolt), each
  // with its command (tests/cli/test_cli_process_engines.cpp runs them).
  std::string allowed;
  for (std::size_t i = 0; i < engine_infos().size(); ++i) {
    const EngineInfo& info = engine_infos()[i];
    EXPECT_EQ(info.command.empty(), i < builtin_count) << info.name;
    allowed += (allowed.empty() ? "" : ", ") + info.name;
  }
  for (const EngineInfo& info : engine_infos()) {
    SCOPED_TRACE(info.name);
    if (!info.command.empty()) continue;  // a process engine: its process runs at the first step
    if (!engine_unavailable(info).empty()) continue;  // cuda without a device
    Scene scene = box_stack();
    scene.midphase = MidphaseConfig::parse("aabb-only");
    apply_engine_options(scene, info, {}, cli_argument_names());
    const auto model = build_model(scene);
    const std::unique_ptr<Engine> e = make_engine(info.name, model);
    EXPECT_EQ(e->name(), info.name);
    EXPECT_EQ(e->broadphase_name() == scene.broadphase.name, info.uses_scene_broadphase) << e->broadphase_name();
    if (!info.uses_scene_broadphase) {
      EXPECT_EQ(e->broadphase_name(), info.own_broadphase);
    }
    EXPECT_EQ(e->midphase_name() == scene.midphase.to_string(), info.has_midphase) << e->midphase_name();
    // records_every_step: judged in process. Bullet records in hull mode (its default)
    // too, but is judged through its trace; in box mode it records nothing.
    // An engine judged in process records every step; a rotating engine that records
    // (mujoco, ode) is judged through its version 2 trace.
    const std::unique_ptr<Engine> boxed = make_engine(info.name, model, {{"bullet", {"shape=box"}}});
    EXPECT_EQ(boxed->can_record() && boxed->rotation_traits() == nullptr, info.records_every_step)
        << "a translation-only scene";
    // octocd's own engines write its contact conventions into their traces
    // (trace_metadata); every other engine declares its own.
    EXPECT_EQ(e->octocd_contacts(), info.name == "cpu" || info.name == "cuda");
    EXPECT_EQ(trace_metadata(*e, 1).declarations.contact_geometry, e->octocd_contacts() ? "aabb" : "");
  }
  // The engines this build has: cpu and bullet always; each of them names a factory.
  const std::vector<std::string> built = built_engine_names();
  EXPECT_NE(std::find(built.begin(), built.end(), "cpu"), built.end());
  EXPECT_NE(std::find(built.begin(), built.end(), "bullet"), built.end());
  {  // Bullet's box mode records nothing (so it is not judged in process either).
    Scene scene = box_stack();
    apply_engine_options(scene, engine_info("bullet", "engine"), {}, cli_argument_names());
    EXPECT_FALSE(make_engine("bullet", build_model(scene), {{"bullet", {"shape=box"}}})->can_record());
  }
  try {
    (void)engine_info("physx", "--engine");
    ADD_FAILURE() << "an unknown engine was accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "--engine: unknown engine 'physx'; allowed: " + allowed);
  }
}

TEST(EngineRegistry, OptionsAnEngineCannotRunAreRefusedInTheCallersSpelling) {
  EngineOptions mid;
  mid.midphase = "1,2";
  EXPECT_EQ(refusal("cpu", mid, cli_argument_names()), "");
  EXPECT_EQ(refusal("bullet", mid, cli_argument_names()),
            "--midphase: engine bullet has no octree midphase (Bullet runs its own narrow phase: "
            "GJK/EPA on convex hulls and triangle meshes, or btBoxBoxDetector on the AABB boxes (--bullet shape=box)); "
            "allowed: no --midphase with --engine bullet");
  EXPECT_EQ(refusal("bullet", mid, python_argument_names()),
            "midphase: engine bullet has no octree midphase (Bullet runs its own narrow phase: "
            "GJK/EPA on convex hulls and triangle meshes, or btBoxBoxDetector on the AABB boxes (--bullet shape=box)); "
            "allowed: None with engine='bullet'");
  EngineOptions bp;
  bp.broadphase = "octree";
  EXPECT_EQ(refusal("bullet", bp, cli_argument_names()),
            "--broadphase: engine bullet runs btDbvtBroadphase, not 'octree'; allowed: bullet-dbvt, or no "
            "--broadphase with --engine bullet");
  bp.broadphase = "lbvh";
  EXPECT_EQ(refusal("cpu", bp, cli_argument_names()),
            "--broadphase: broadphase 'lbvh' exists on the device only; allowed: --engine cuda with it, or another "
            "broadphase");
  EXPECT_EQ(refusal("cuda", bp, cli_argument_names()), "");
  bp.broadphase = "kd-tree";
  EXPECT_NE(refusal("cuda", bp, python_argument_names())
                .find("broadphase: unknown broadphase 'kd-tree'; allowed: flat, octree"),
            std::string::npos);
  EngineOptions rot;
  rot.rotation = true;
  EXPECT_EQ(refusal("cpu", rot, cli_argument_names()),
            "--rotation: engine cpu translates only (design.md section 3); allowed: --rotation with --engine bullet");
  EXPECT_EQ(refusal("bullet", rot, cli_argument_names()), "");
}

// An engine with a measured size limit (EngineInfo::max_bodies: mujoco 12,000, dart 20,000)
// refuses a larger model at once, before any set-up (MuJoCo's compile is quadratic:
// 11-48 CPU s at 10^4, about 1,100 CPU s at 10^5; DART's set-up of 10^5 takes minutes), naming the count, the
// limit and the measured reason; at the limit it is not refused for its size.
TEST(EngineRegistry, AnEngineRefusesAModelAboveItsMeasuredLimitAtOnce) {
  for (const char* name : {"mujoco", "dart"}) {
    SCOPED_TRACE(name);
    const EngineInfo& info = engine_info(name, "test");
    ASSERT_GT(info.max_bodies, 0u);
    ASSERT_FALSE(info.max_bodies_reason.empty());
    const std::string scene = R"({"name": "many", "domain": {"min": [-40, -40, -40], "max": [40, 40, 40]},
        "gravity": [0, 0, 0], "walls": "none", "groups": [{"name": "b", "shape": {"box": [0.01, 0.01, 0.01]},
        "count": )" + std::to_string(info.max_bodies + 1) + R"(, "mass": 1, "layout": {"type": "random", "seed": 1}}]})";
    const auto model = build_model(parse_scene(scene, "many.json"));
    ASSERT_EQ(model->bodies.size(), info.max_bodies + 1);
    std::string what;
    try {
      (void)make_engine(name, model);
    } catch (const RuntimeError& e) {
      what = e.what();
    }
    EXPECT_NE(what.find(fmt::format("engine {} does not start {} bodies: above its measured limit of {} bodies (",
                                    name, info.max_bodies + 1, info.max_bodies)),
              std::string::npos)
        << what;
  }
  EXPECT_EQ(engine_info("bullet", "test").max_bodies, 0u) << "Bullet starts 10^5 bodies in 6-7 CPU s";
}

}  // namespace octocd_test_engine_registry
