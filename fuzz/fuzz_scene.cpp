// libFuzzer target: the scene loader (issue 10). Any text is parsed as a scene; a scene
// that loads, has no meshes (no file access) and at most 500 bodies is built and run for
// 3 frames on the CPU engine with `flat` and its own broadphase. Bad input must end in
// InputError (exit 2), a failing run in RuntimeError (exit 1); anything else (a crash, a
// sanitizer report, another exception) is a finding.
#include <cstddef>
#include <cstdint>
#include <string>

#include "octocd/broadphase.hpp"
#include "octocd/engine.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  octocd::Scene scene;
  try {
    scene = octocd::parse_scene(text, "fuzz/scene.json", "/nonexistent-octocd-fuzz-data");
  } catch (const octocd::InputError&) {
    return 0;
  }
  if (octocd::body_count(scene) > 500) return 0;
  for (const auto& g : scene.groups)
    if (g.shape.kind == octocd::ShapeSpec::Kind::Mesh) return 0;
  for (const char* bp : {"flat", ""}) {
    try {
      octocd::Scene s = scene;
      if (*bp) s.broadphase.name = bp;
      octocd::World world(s);
      for (int f = 0; f < 3; ++f) world.step();
    } catch (const octocd::InputError&) {
    } catch (const octocd::RuntimeError&) {
    }
  }
  return 0;
}
