// Validation cost at scale (issue 33 item 6): the time to judge one frame of N bodies, per
// frame and per body-frame, for
//   physics   the physics tier alone, as `validate --trace-in` judges another engine
//             (FrameValidators with an external source: FCL/SAT truth per candidate pair,
//             the reference pair set, contact rows, dynamics rows), on a checked frame;
//   full      both tiers as `octocd validate` judges octocd's own engine (candidate sets
//             of octocd's broadphases against the reference pair set, midphase, Eq. 14,
//             applied state), without the Bullet/FCL broadphases;
//   pairs     the reference pair set alone (exact_pairs) and, up to 2 x 10^4 bodies,
//             the `flat` broadphase it replaces.
// The scene (default datasets/scenes/boxes-uniform-100k.json) is scaled to N bodies at its
// own density: every group's count times N / N0, the domain and every layout box times
// (N / N0)^(1/3). The CPU engine runs --warmup frames (not timed) and records the next one;
// each repetition judges that record on fresh validators. Reported: median, min and max
// over --reps repetitions, the contact rows of the frame, the validators' threads
// (--threads: a list, 0 the hardware's), the median CPU time of the process over the
// same span (user + system, every thread: steadier than the wall time on a shared
// machine) and the 1-minute load average.
// --lattice instead judges a contact-heavy frame: N boxes (half extent 0.1 m) on a cubic
// grid of spacing 0.19 m, no gravity, so every box overlaps its 26 neighbours by 1 cm
// (about 13 contact pairs a body); the engine's first step is recorded (--warmup 0).
// --rows: each row's own seconds a frame (its clock over the frames its validators judged).
// --same-judge: each repetition judges the record again on the same validators, which
// judged it once untimed first: a run's frames after its first (the validators keep a
// checked frame's tables for the next one), where the default times a run's first frame.
// --judge-device cuda: the physics tier's rows broadphase-completeness and penetration on
// the GPU (ValidationOptions::judge_device, octocd/device_judge.hpp); with --rows their own
// seconds are the device rows' time a frame (the CPU rows' shared geometry then goes to
// contact-completeness, the first CPU row that asks).
// --json FILE writes the physics verdict of the last repetition (results_json, each row's
// seconds set to 0) for every size and thread count, one document per line, so that a
// change meant only for speed can be checked to leave the verdict unchanged (diff). The
// file is written at the end through octocd/atomic_file.hpp (a temporary beside it renamed
// over a regular file; a FIFO, device, folder or link there is exit 2 before any work).
//
// A bad option value or scene file (missing, unreadable, not a scene, no bodies) is exit 2
// with an error naming it and what is allowed; the default scene is the source tree's, so
// a binary run away from it needs SCENE.json (or --lattice).
//
// Usage: bench_validation [SCENE.json] [--bodies 20000,100000] [--reps 5] [--warmup 20]
//                         [--only physics,full,pairs] [--rows] [--threads 1,2] [--lattice]
//                         [--same-judge] [--judge-device cpu|cuda] [--json FILE]
#include <thread>

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "octocd/atomic_file.hpp"
#include "octocd/device_judge.hpp"
#include "octocd/error.hpp"
#include "octocd/exact_pairs.hpp"
#include "octocd/expect.hpp"
#include "octocd/physics.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/scene.hpp"
#include "octocd/validation.hpp"
#include "octocd/world.hpp"

namespace {

using Clock = std::chrono::steady_clock;

/// The process's CPU time (s): user + system, every thread.
double cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

double load_average() {
  std::ifstream in("/proc/loadavg");
  double l = -1;
  in >> l;
  return l;
}

/// The comma-separated integers of option `option`, each in [lo, hi]; InputError naming the
/// option, the item and the allowed range otherwise.
std::vector<long> parse_list(const std::string& option, const std::string& s, long lo, long hi) {
  std::vector<long> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) {
    std::size_t used = 0;
    long v = 0;
    try {
      v = std::stol(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != item.size() || v < lo || v > hi)
      throw octocd::InputError(fmt::format("{}: '{}' in '{}'; allowed: a comma-separated list of integers in [{}, {}]",
                                           option, item, s, lo, hi));
    out.push_back(v);
  }
  if (out.empty())
    throw octocd::InputError(fmt::format("{}: empty; allowed: a comma-separated list of integers in [{}, {}]", option,
                                         lo, hi));
  return out;
}

/// The scene at `path` scaled to about `bodies` bodies at its own density. The file is
/// read and checked as `octocd run` reads a scene (load_scene: InputError naming the
/// file, the key and the allowed range); a scene without groups of bodies is InputError.
octocd::Scene scaled_scene(const std::string& path, long bodies) {
  try {
    octocd::load_scene(path);  // every check of a scene file, with its own errors
  } catch (const octocd::InputError& e) {
    throw octocd::InputError(fmt::format("{} (the scene modes scale a scene file: give SCENE.json, by default "
                                         "datasets/scenes/boxes-uniform-100k.json of the source tree, or --lattice)",
                                         e.what()));
  }
  nlohmann::json j = nlohmann::json::parse(
      octocd::read_input_file(path, "SCENE", "a readable JSON scene file", octocd::limits::kMaxSceneFileBytes));
  long n0 = 0;
  if (j.contains("groups"))
    for (const auto& g : j["groups"]) n0 += g.value("count", 0L);
  if (n0 <= 0)
    throw octocd::InputError(fmt::format("SCENE: {}: groups: no bodies to scale; allowed: a scene whose groups "
                                         "give their counts (e.g. datasets/scenes/boxes-uniform-100k.json), or --lattice",
                                         path));
  const double ratio = double(bodies) / double(n0), s = std::cbrt(ratio);
  auto scale3 = [&](nlohmann::json& v) {
    for (auto& c : v) c = c.get<double>() * s;
  };
  scale3(j["domain"]["min"]);
  scale3(j["domain"]["max"]);
  for (auto& g : j["groups"]) {
    g["count"] = std::max(1L, std::lround(double(g["count"].get<long>()) * ratio));
    if (g.contains("layout")) {
      if (g["layout"].contains("min")) scale3(g["layout"]["min"]);
      if (g["layout"].contains("max")) scale3(g["layout"]["max"]);
    }
  }
  j["name"] = fmt::format("{}-{}", j["name"].get<std::string>(), bodies);
  return octocd::parse_scene(j.dump(), path);
}

/// `bodies` boxes (half extent 0.1 m) on a cubic grid of spacing 0.19 m: each overlaps its
/// 26 neighbours by 0.01 m on every axis. No gravity, no walls.
octocd::Scene lattice_scene(long bodies) {
  const long side = std::lround(std::ceil(std::cbrt(double(bodies)) - 1e-9));
  const double s = 0.19, half = 0.5 * double(side - 1) * s + 0.1;
  nlohmann::json j = {{"name", fmt::format("box-lattice-{}", bodies)},
                      {"domain", {{"min", {-half - 0.5, -half - 0.5, -half - 0.5}},
                                  {"max", {half + 0.5, half + 0.5, half + 0.5}}}},
                      {"gravity", {0.0, 0.0, 0.0}},
                      {"walls", "none"},
                      {"groups",
                       {{{"name", "lattice"},
                         {"shape", {{"box", {0.1, 0.1, 0.1}}}},
                         {"count", bodies},
                         {"mass", 1.0},
                         {"layout",
                          {{"type", "grid"},
                           {"min", {-half, -half, -half}},
                           {"max", {half + 1e-3, half + 1e-3, half + 1e-3}},
                           {"spacing", s}}}}}}};
  return octocd::parse_scene(j.dump(), "lattice");
}

struct Stats {
  double median, min, max;
};
Stats stats(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return {v[v.size() / 2], v.front(), v.back()};
}

}  // namespace

int bench(int argc, char** argv);

int main(int argc, char** argv) {
  // A bad option or scene is exit 2 with its error; any other failure exit 1.
  try {
    return bench(argc, argv);
  } catch (const octocd::InputError& e) {
    std::fprintf(stderr, "bench_validation: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_validation: %s\n", e.what());
    return 1;
  }
}

int bench(int argc, char** argv) {
  std::string scene_path = std::string(OCTOCD_SOURCE_DIR) + "/datasets/scenes/boxes-uniform-100k.json";
  std::vector<long> sizes{20000, 100000};
  int reps = 5, warmup = 20;
  std::string only = "physics,full,pairs";
  bool rows_shown = false;  // --rows: each row's own seconds on the last repetition
  bool lattice = false;     // --lattice: the contact-heavy box lattice instead of SCENE
  bool same_judge = false;  // --same-judge: the repetitions on one set of validators (see time_observe)
  std::vector<long> thread_counts{0};
  std::string json_path;    // --json FILE: the physics verdicts, one JSON document a line
  // --judge-device NAME: rows 1 and 4 on that device (null: the CPU)
  std::unique_ptr<octocd::DeviceJudge> (*judge_make)() = nullptr;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "%s: missing value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--bodies") sizes = parse_list(a, next(), 1, long(octocd::limits::kMaxGeneratedBodies));
    else if (a == "--reps") reps = int(parse_list(a, next(), 1, 1000000).at(0));
    else if (a == "--warmup") warmup = int(parse_list(a, next(), 0, 1000000).at(0));
    else if (a == "--only") only = next();
    else if (a == "--rows") rows_shown = true;
    else if (a == "--lattice") lattice = true;
    else if (a == "--same-judge") same_judge = true;
    else if (a == "--threads") thread_counts = parse_list(a, next(), 0, 4096);
    else if (a == "--json") json_path = next();
    else if (a == "--judge-device") {
      try {
        judge_make = octocd::judge_device_kind(next(), "--judge-device").make;
      } catch (const std::invalid_argument& e) {
        std::fprintf(stderr, "%s\n", e.what());
        return 2;
      }
    }
    else if (!a.empty() && a[0] != '-') scene_path = a;
    else {
      std::fprintf(stderr, "usage: bench_validation [SCENE.json] [--bodies N,..] [--reps R] [--warmup W] [--only ...] "
                           "[--rows] [--threads T,..] [--lattice] [--same-judge] [--judge-device cpu|cuda] [--json FILE]\n");
      return 2;
    }
  }
  // --json: checked before any work, written once at the end as every octocd output is
  // (octocd/atomic_file.hpp: a temporary beside it renamed over a regular file only).
  std::string json_text;
  if (!json_path.empty()) {
    try {
      octocd::check_output_file(json_path, "--json");
    } catch (const octocd::InputError& e) {
      std::fprintf(stderr, "bench_validation: %s\n", e.what());
      return 2;
    }
  }
  auto wanted = [&](const char* what) { return ("," + only + ",").find(std::string(",") + what + ",") != std::string::npos; };
  fmt::print("bench_validation: {} hardware threads, load average {:.2f} at start, {} repetitions\n",
             std::thread::hardware_concurrency(), load_average(), reps);
  fmt::print("{:<10} {:>8} {:>9} {:>9} {:>7} {:>10} {:>10} {:>10} {:>14} {:>9} {:>8}\n", "what", "bodies", "pairs",
             "contacts", "threads", "median s", "min s", "max s", "us/body-frame", "cpu s", "load");
  for (long target : sizes) {
    const octocd::Scene scene = lattice ? lattice_scene(target) : scaled_scene(scene_path, target);
    const std::shared_ptr<const octocd::Model> model = octocd::build_model(scene);
    octocd::World world(model, octocd::make_any_broadphase(scene.broadphase, scene.domain));
    world.set_recording(true);
    for (int f = 0; f <= (lattice ? 0 : warmup); ++f) world.step();
    const octocd::FrameRecord rec = world.record();
    const long n = long(rec.aabbs.size());
    std::vector<octocd::Pair> pairs;
    octocd::exact_pairs(rec.aabbs, pairs);
    long threads = 0;
    // Per repetition: wall seconds (t) and process CPU seconds (cpu) of the timed span.
    std::vector<double> cpu;
    auto row = [&](const char* what, const std::vector<double>& t) {
      const Stats st = stats(t);
      fmt::print("{:<10} {:>8} {:>9} {:>9} {:>7} {:>10.4f} {:>10.4f} {:>10.4f} {:>14.3f} {:>9.4f} {:>8.2f}\n", what,
                 n, pairs.size(), rec.contacts.size(),
                 threads > 0 ? threads : long(std::thread::hardware_concurrency()), st.median, st.min, st.max,
                 1e6 * st.median / double(n), cpu.empty() ? 0.0 : stats(cpu).median, load_average());
      cpu.clear();
      std::fflush(stdout);
    };
    octocd::ValidationOptions vo;
    vo.against_fcl = false;
    vo.against_bullet = false;
    if (judge_make) vo.judge_device = judge_make;
    for (long th : thread_counts) {
    threads = th;
    vo.threads = int(th);
    // Times `reps` observations of `rec` by fresh validators from `make`; after the last one
    // prints the slow rows (rows_shown) and, with `verdict` and --json, appends the verdict.
    // With --same-judge the repetitions judge `rec` again on one set of validators that
    // judged it once untimed (a run's frames after its first), and the verdict written is
    // that first judgement's (a fresh set's).
    auto time_observe = [&](const char* what, auto make, bool verdict) {
      std::vector<double> t;
      auto write_verdict = [&](const octocd::FrameValidators& v) {
        if (!verdict || json_path.empty()) return;
        std::vector<octocd::ValidationResult> results = v.results();
        for (octocd::ValidationResult& x : results) x.seconds = 0;  // the verdict only
        json_text += octocd::results_json(results, octocd::RunName{scene.name, ""},
                                          nullptr, {{"threads", th}}).dump() + "\n";
      };
      std::unique_ptr<octocd::FrameValidators> kept;
      if (same_judge) {
        kept.reset(new octocd::FrameValidators(make()));
        kept->observe(rec, true);
        write_verdict(*kept);
      }
      for (int r = 0; r < reps; ++r) {
        std::unique_ptr<octocd::FrameValidators> fresh;
        if (!same_judge) fresh.reset(new octocd::FrameValidators(make()));
        octocd::FrameValidators& v = same_judge ? *kept : *fresh;
        const double c0 = cpu_seconds();
        const auto t0 = Clock::now();
        v.observe(rec, true);
        t.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
        cpu.push_back(cpu_seconds() - c0);
        if (r + 1 == reps && rows_shown) {
          // The rows' clocks sum every frame these validators judged (--same-judge: all of them).
          const int frames = same_judge ? reps + 1 : 1;
          for (const octocd::ValidationResult& x : v.results())
            if (x.seconds > 1e-3 * frames)
              fmt::print("  {:<28} {:.4f} s a frame{}\n", x.name, x.seconds / frames,
                         x.detail.find("judged on the device") != std::string::npos ? " (device row)" : "");
          for (const octocd::ValidationResult& x : v.results()) {
            const std::size_t at = x.detail.find("judged on the device");
            if (x.name == "broadphase-completeness" && at != std::string::npos)
              fmt::print("  {}\n", x.detail.substr(at, x.detail.find("; causes:", at) - at));
          }
        }
        if (r + 1 == reps && !same_judge) write_verdict(v);
      }
      row(what, t);
    };
    if (wanted("physics"))
      time_observe("physics", [&] {
        return octocd::FrameValidators(*model, vo, {},
                                       octocd::FrameValidators::Source{"engine 'bench'", false, false, nullptr});
      }, true);
    if (wanted("full"))
      time_observe("full", [&] {
        return octocd::FrameValidators(world, vo, octocd::compared_broadphases(scene, false));
      }, false);
    }
    if (wanted("pairs")) {
      std::vector<double> t, tf;
      std::vector<octocd::Pair> out;
      for (int r = 0; r < reps; ++r) {
        const double c0 = cpu_seconds();
        const auto t0 = Clock::now();
        octocd::exact_pairs(rec.aabbs, out);
        t.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
        cpu.push_back(cpu_seconds() - c0);
      }
      row("exact", t);
      if (n <= 25000) {
        octocd::BroadPhaseConfig cfg;
        cfg.name = octocd::broadphase_name(octocd::BroadPhaseId::flat);
        auto flat = octocd::make_broadphase(cfg, scene.domain);
        octocd::BroadPhaseStats bs;
        for (int r = 0; r < reps; ++r) {
          const double c0 = cpu_seconds();
          const auto t0 = Clock::now();
          flat->find_pairs(rec.aabbs, out, bs);
          tf.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
          cpu.push_back(cpu_seconds() - c0);
        }
        row(cfg.name.c_str(), tf);
      }
    }
  }
  if (!json_path.empty()) {
    try {
      octocd::write_file_atomically(json_path, json_text, "--json");
    } catch (const std::exception& e) {
      std::fprintf(stderr, "bench_validation: %s\n", e.what());
      return dynamic_cast<const octocd::InputError*>(&e) ? 2 : 1;
    }
  }
  return 0;
}
