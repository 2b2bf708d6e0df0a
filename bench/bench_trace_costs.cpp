// Where a traced run's frame goes (issue 56 item 1), as `octocd run --trace` feeds a trace
// (cli::TraceFeed): per scene and trace mode, steps/s of the whole frame and the mean
// microseconds of its parts.
//   off       no trace: the engine runs ahead of the calls (Engine::plan_steps, all frames);
//   states    a version 1 trace with the state every --state-every frames: the engine runs
//             ahead to the next state frame, state() copies the state back there;
//   contacts  with every contact row too (Engine::set_recording), all frames promised as
//             cli::TraceFeed does: the cuda engine's resident kernel runs recorded steps in
//             batches of CudaSettings::record_batch and copies their records back once a
//             batch (--cuda record_batch=1: a request and a copy-back per step, no step ahead).
// Columns: step (Engine::step, with the recording's copies in contacts mode), of it the first
// step of each batch (a new request to the resident kernel), state() per call, append
// (TraceWriter::append_frame: buffering, and waiting for the writer thread when a flush is due)
// and the trace's size. The traces use cli::kTraceFlushIntervalS as `run --trace` does
// (--flush-interval overrides: 0 flushes every 50 frames, TraceOptions' default).
// With --profile the contacts lines also print CudaWorld::small_profile (the kernel's time
// against the host's round trip; stamped steps run one a request, so with record_batch > 1
// the profile changes the contacts mode's batches). --cuda KEY=VALUE (repeatable) sets a
// cuda setting for every mode (docs/settings.md), e.g. record_batch=1 against the default.
//
// Per scene and repetition (--repeat, the modes interleaved): a fresh engine, --warmup
// untraced steps, then --frames traced ones. Reported: median steps/s with the smallest and
// largest, the ratio to off (median of the repetitions' ratios), and the parts' means over
// the repetitions. The traces go to $TMPDIR and are removed.
//
// Usage: bench_trace_costs SCENE.json... [--engine cuda] [--frames 2000] [--warmup 30]
//          [--repeat 5] [--state-every 10] [--modes off,states,contacts] [--flush-interval S]
//          [--profile] [--cuda KEY=VALUE]...
// Exit: 0; 1 runtime error (e.g. no CUDA device for --engine cuda); 2 bad arguments.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "octocd/cuda_world.hpp"
#include "octocd/engine.hpp"
#include "octocd/engines.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/trace.hpp"
#include "bench_main.hpp"
#include "tools.hpp"

using namespace octocd;

namespace {

using Clock = std::chrono::steady_clock;

double us_since(Clock::time_point t) { return std::chrono::duration<double, std::micro>(Clock::now() - t).count(); }

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

/// One repetition of one mode: steps/s and the parts' totals (us).
struct Sample {
  double steps_per_s = 0.0;
  double step_us = 0.0, first_us = 0.0, state_us = 0.0, append_us = 0.0;
  int firsts = 0, states = 0;
  double trace_mb = 0.0;
  std::string profile;
};

struct Options {
  std::string engine = "cuda";
  int frames = 2000, warmup = 30, repeat = 5, state_every = 10;
  double flush_interval = cli::kTraceFlushIntervalS;
  bool profile = false;
  std::vector<std::string> cuda;  // --cuda KEY=VALUE items, every mode
};

Sample run_mode(const std::shared_ptr<const Model>& model, const std::string& mode, const Options& o) {
  const bool traced = mode != "off", contacts = mode == "contacts";
  EngineSettingItems settings;
  if (!o.cuda.empty()) settings["cuda"] = o.cuda;
  if (o.profile && contacts) settings["cuda"].push_back("small_profile=true");  // other engines ignore it
  std::unique_ptr<Engine> e = make_engine(o.engine, model, settings);
  e->plan_steps(o.warmup);
  for (int f = 0; f < o.warmup; ++f) e->step();
  std::unique_ptr<TraceWriter> trace;
  std::string path;
  if (traced) {
    path = (std::filesystem::temp_directory_path() / fmt::format("octocd-trace-costs-{}.h5", ::getpid())).string();
    TraceOptions topt;
    topt.state_every = o.state_every;
    topt.contacts = contacts && e->can_record();
    topt.flush_interval_s = o.flush_interval;
    if (topt.contacts) e->set_recording(true);
    trace = std::make_unique<TraceWriter>(path, trace_metadata(*e, o.state_every), trace_bodies(*e), topt);
    trace->append_state(0, e->state());
  }
  const bool ahead = !contacts;  // as cli::TraceFeed: a states-only feed runs ahead between state frames
  const auto to_next_state = [&](std::int64_t frame) {
    return static_cast<std::int64_t>(o.state_every) - frame % o.state_every;
  };
  Sample s;
  if (!traced) e->plan_steps(o.frames);
  else if (ahead) e->plan_steps(std::min<std::int64_t>(to_next_state(0), o.frames));
  else e->plan_steps(o.frames);  // contacts: as cli::TraceFeed promises a recording engine's steps
  bool batch_start = true;
  const auto t0 = Clock::now();
  for (int f = 1; f <= o.frames; ++f) {
    auto t = Clock::now();
    FrameMetrics m = e->step();
    const double step = us_since(t);
    s.step_us += step;
    if (traced && ahead && batch_start) {
      s.first_us += step;
      ++s.firsts;
      batch_start = false;
    }
    if (!traced) continue;
    m.frame = f;  // the trace's frames count from the warm-up's end
    const bool due = trace->state_due(f);
    const BodyState* state = nullptr;
    if (due) {
      t = Clock::now();
      state = &e->state();
      s.state_us += us_since(t);
      ++s.states;
    }
    t = Clock::now();
    trace->append_frame(m, state, e->contacts());
    s.append_us += us_since(t);
    if (ahead && due) {
      e->plan_steps(std::min<std::int64_t>(to_next_state(f), o.frames - f));
      batch_start = true;
    }
  }
  s.steps_per_s = o.frames / (us_since(t0) * 1e-6);
  if (trace) {
    trace->close();
    std::error_code ec;
    s.trace_mb = static_cast<double>(std::filesystem::file_size(path, ec)) / (1024.0 * 1024.0);
    std::filesystem::remove(path, ec);
  }
  if (auto* c = dynamic_cast<CudaWorld*>(e.get()); c && o.profile && contacts) s.profile = c->small_profile();
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Where a traced run's frame goes: the step, the copy-back and the trace write, per trace mode"};
  std::vector<std::string> scenes;
  std::vector<std::string> modes = {"off", "states", "contacts"};
  Options o;
  app.add_option("scenes", scenes, "scene files")->required()->check(CLI::ExistingFile);
  app.add_option("--engine", o.engine, "engine of the registry (cuda, cpu, ...)");
  app.add_option("--frames", o.frames, "traced steps per repetition")->check(CLI::Range(1, 10000000));
  app.add_option("--warmup", o.warmup, "untraced steps first")->check(CLI::Range(0, 10000000));
  app.add_option("--repeat", o.repeat, "repetitions (fresh engine each)")->check(CLI::Range(1, 1000));
  app.add_option("--state-every", o.state_every, "state rows every K frames")->check(CLI::Range(1, 1000000));
  app.add_option("--modes", modes, "off, states, contacts")
      ->delimiter(',')
      ->check(CLI::IsMember({"off", "states", "contacts"}));
  app.add_option("--flush-interval", o.flush_interval, "TraceOptions::flush_interval_s (s)")
      ->check(CLI::Range(0.0, 3600.0));
  app.add_option("--cuda", o.cuda, "a cuda setting for every mode, KEY=VALUE, repeatable (docs/settings.md)");
  app.add_flag("--profile", o.profile, "contacts lines: the small path's kernel profile (CudaSettings::small_profile)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  return octocd::bench::exit_code_of("bench_trace_costs", [&] {
    fmt::print("| scene | bodies | mode | steps/s median | min | max | vs off | step us | batch's first step us | "
               "state() us a call | append us | trace MiB |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (const std::string& file : scenes) {
      const std::shared_ptr<const Model> model = build_model(load_scene(file));
      std::vector<std::vector<Sample>> samples(modes.size());
      for (int r = 0; r < o.repeat; ++r)
        for (std::size_t i = 0; i < modes.size(); ++i) samples[i].push_back(run_mode(model, modes[i], o));
      const auto off = std::find(modes.begin(), modes.end(), "off");
      for (std::size_t i = 0; i < modes.size(); ++i) {
        std::vector<double> rate, ratio;
        Sample mean;
        for (std::size_t r = 0; r < samples[i].size(); ++r) {
          const Sample& s = samples[i][r];
          rate.push_back(s.steps_per_s);
          if (off != modes.end()) ratio.push_back(s.steps_per_s / samples[static_cast<std::size_t>(off - modes.begin())][r].steps_per_s);
          mean.step_us += s.step_us;
          mean.first_us += s.first_us;
          mean.firsts += s.firsts;
          mean.state_us += s.state_us;
          mean.states += s.states;
          mean.append_us += s.append_us;
          mean.trace_mb += s.trace_mb / static_cast<double>(samples[i].size());
        }
        const double steps = static_cast<double>(o.frames) * static_cast<double>(samples[i].size());
        const auto [lo, hi] = std::minmax_element(rate.begin(), rate.end());
        fmt::print("| {} | {} | {} | {:.0f} | {:.0f} | {:.0f} | {} | {:.2f} | {} | {} | {:.2f} | {:.2f} |\n",
                   model->scene.name, model->initial.size(), modes[i], median(rate), *lo, *hi,
                   ratio.empty() ? std::string("") : fmt::format("{:.2f}", median(ratio)), mean.step_us / steps,
                   mean.firsts ? fmt::format("{:.2f}", mean.first_us / mean.firsts) : std::string(""),
                   mean.states ? fmt::format("{:.2f}", mean.state_us / mean.states) : std::string(""),
                   mean.append_us / steps, mean.trace_mb);
        if (!samples[i].back().profile.empty()) fmt::print("\n{} contacts: {}\n\n", model->scene.name, samples[i].back().profile);
        std::fflush(stdout);
      }
    }
    return 0;
  });
}
