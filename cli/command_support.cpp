// What `run` and `validate` share (command_support.hpp).
#include "command_support.hpp"

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <system_error>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/process_engines.hpp"
#include "octocd/stop.hpp"
#include "octocd/text.hpp"
#include "octocd/trace_reader.hpp"

namespace octocd::cli {

std::string engines_help() {
  return "The engine that steps the scene (`octocd engines` describes each and says which are available here; "
         "docs/engines.md)";
}

std::string engines_with(bool (*has)(const EngineInfo&)) {
  std::string text;
  for (const EngineInfo& e : engine_infos())
    if (has(e)) text += (text.empty() ? "--engine " : ", --engine ") + e.name;
  return text;
}

std::string data_dir_help() {
  return
         "Folder of the dataset meshes (NAME.obj|.off|.ply); default: $OCTOCD_DATA_DIR, else "
         "<scene folder>/../cache, else the datasets/cache of the shared files (PREFIX/share/octocd when installed, else "
         "the source tree; docs/scenes.md)";
}

void check_engine_inertia(const octocd::Engine& world, const octocd::Model& model, const std::string& engine) {
  namespace lim = octocd::trace_limits;
  const octocd::RotationTraits* traits = world.rotation_traits();
  if (!traits || !traits->rotates) return;
  const octocd::BodyState& s = world.state();
  for (std::size_t i = 0; i < traits->inertia.size() && i < s.size(); ++i) {
    if (!(s.w[i] > 0.0f)) continue;  // static: never used
    const auto& m = traits->inertia[i];
    for (int k = 0; k < 3; ++k) {
      const double d = m[static_cast<std::size_t>(4 * k)];
      if (std::isfinite(d) && d >= lim::kMinInertia && d <= lim::kMaxInertia) continue;
      const octocd::BodyInfo& b = model.bodies[i];
      throw octocd::InputError(fmt::format(
          "scene '{}': body {} (group '{}', shape '{}'): engine {} gives it inertia I[{}][{}] = {:g} kg m^2: the "
          "shape cannot give a positive inertia a trace may hold; allowed: diagonal moments in [{:g}, {:g}] kg m^2 "
          "for a dynamic body (docs/trace-format.md, \"Security rules and limits\"): a shape of volume, not a "
          "needle, a flat or a collinear mesh",
          octocd::printable(model.scene.name), i, octocd::printable(b.group),
          octocd::printable(model.shapes[b.shape].name), engine, k, k, d, lim::kMinInertia, lim::kMaxInertia));
    }
  }
}

void check_engine_state(const octocd::BodyState& state, std::int64_t frame, const std::string& engine) {
  namespace lim = octocd::trace_limits;
  const auto bad = [&](std::size_t i, const char* what, const octocd::Vec3& v, const char* unit, double bound) {
    return octocd::RuntimeError(fmt::format(
        "engine {}: frame {}: body {}: its {} ({:g}, {:g}, {:g}) {} is {}; allowed: finite components within +-{:g} "
        "{} (what a trace may hold: docs/trace-format.md, \"Security rules and limits\"); the run stops before "
        "writing frame {}",
        engine, frame, i, what, v.x, v.y, v.z, unit,
        std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z) ? "out of range" : "not finite", bound, unit,
        frame));
  };
  const auto within = [](const octocd::Vec3& v, double bound) {
    return std::fabs(v.x) <= bound && std::fabs(v.y) <= bound && std::fabs(v.z) <= bound;  // NaN fails
  };
  for (std::size_t i = 0; i < state.size(); ++i) {
    if (!within(state.x[i], lim::kMaxCoordinate)) throw bad(i, "position", state.x[i], "m", lim::kMaxCoordinate);
    if (!within(state.v[i], lim::kMaxSpeed)) throw bad(i, "velocity", state.v[i], "m/s", lim::kMaxSpeed);
    if (i < state.omega.size() && !within(state.omega[i], lim::kMaxAngularSpeed))
      throw bad(i, "angular velocity", state.omega[i], "rad/s", lim::kMaxAngularSpeed);
  }
}

/// Loads the scene for `run` and `validate`: `--data-dir` (checked to be a folder) or the
/// default lookup of docs/scenes.md.
octocd::Scene load_scene_for(const std::string& path, const std::string& data_dir) {
  if (!data_dir.empty()) {
    std::error_code ec;
    if (!std::filesystem::is_directory(data_dir, ec))
      throw octocd::InputError(fmt::format(
          "--data-dir: '{}' is not a folder; allowed: a folder holding the dataset meshes (NAME.obj, "
          "NAME.off or NAME.ply), e.g. datasets/cache",
          data_dir));
  }
  return octocd::load_scene(path, data_dir);
}

/// Writes the XDMF sidecar of a finished (or stopped) trace unless `--no-xdmf`; returns
/// its path ("" when not written).
std::string write_sidecar(const std::string& trace, bool no_xdmf) {
  if (trace.empty() || no_xdmf) return "";
  return octocd::write_xdmf_sidecar(trace);
}

/// After a runtime failure: closes the trace and writes its sidecar as far as the disk
/// allows. A failure here is dropped on purpose: the original error (e.g. the full disk
/// that stopped the trace) is the one line the user must see.
void close_after_failure(std::unique_ptr<octocd::TraceWriter>& trace, const std::string& path, bool no_xdmf) {
  if (!trace) return;
  try {
    const bool failed = trace->failed();  // an abandoned file (full disk): no sidecar, no read-back
    trace->close();                       // keep every frame written so far readable
    if (!failed) write_sidecar(path, no_xdmf);
  } catch (const std::exception&) {
  }
}

/// An integer option in [1, 2147483647], with the message in the project's form
/// ("--frames: 0 is out of range; allowed: an integer in [1, 2147483647]") instead of
/// CLI11's PositiveNumber, which prints the range of a double.
CLI::Validator at_least_one() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        long long v = 0;
        std::size_t used = 0;
        try {
          v = std::stoll(text, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        if (used == 0 || used != text.size())
          return "'" + text + "' is not an integer; allowed: an integer in [1, 2147483647]";
        if (v < 1 || v > INT_MAX) return text + " is out of range; allowed: an integer in [1, 2147483647]";
        return "";
      },
      "");  // the option's own help says ">= 1"
}

std::vector<std::string> ProcessProgressLines::next(const ProcessProgress& p) {
  constexpr double kQuietS = 10.0;  // the longest silence while it runs
  std::vector<std::string> lines;
  const std::int64_t tenth = p.stepped < 0 ? 0 : 10 * p.stepped / std::max<std::int64_t>(p.frames, 1);
  const bool start = p.stepped >= 0 && !started_;
  if (!start && (!tenths_ || tenth <= tenth_) && p.seconds - said_s_ < kQuietS) return lines;
  if (start) {
    started_ = true;
    lines.push_back(fmt::format("engine {}: its process started in {:.2f} s; stepping", name_, p.started_s));
  }
  if (p.stepped < 0) {
    lines.push_back(fmt::format("engine {}: its process is still starting after {:.0f} s", name_, p.seconds));
  } else if ((tenths_ && tenth > tenth_) || !start) {
    const double stepping_s = p.seconds - p.started_s;
    lines.push_back(fmt::format("frame {}/{}  {:.1f} frames/s  (its process as it runs, trace writing included)",
                                p.stepped, p.frames,
                                stepping_s > 0.0 ? static_cast<double>(p.stepped) / stepping_s : 0.0));
  }
  said_s_ = p.seconds;
  tenth_ = std::max(tenth_, tenth);
  return lines;
}

void show_process_progress(Engine& world, std::int64_t frames, bool shown) {
  if (!shown || !world.writes_own_trace()) return;
  const std::string name = printable(world.name());
  std::fflush(stdout);  // stdout and stderr to one file: the lines in the order they happened
  std::fprintf(stderr, "engine %s: starting %s for %lld frames; its steps are said as its process reports them, "
               "then its frames are read from its trace\n",
               name.c_str(), printable(world.device()).c_str(), static_cast<long long>(frames));
  std::fflush(stderr);
  auto said = std::make_shared<ProcessProgressLines>(name, true);
  set_process_progress(world, [said](const ProcessProgress& p) {
    const std::vector<std::string> lines = said->next(p);
    if (lines.empty()) return;
    std::fflush(stdout);
    for (const std::string& line : lines) std::fprintf(stderr, "%s\n", line.c_str());
    std::fflush(stderr);
  });
}

}  // namespace octocd::cli
