// `octocd replay` (design.md section 12): recorded world AABBs through several broadphases, each fed
// exactly the same input (the Broadmark method), checked against each other and against
// the recorded pair counts, and timed. The replay core here also serves the
// broadphase-scaling sweeps of `octocd bench` (cli/bench.cpp).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <tuple>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/trace_reader.hpp"
#include "octocd/world.hpp"
#include "command_support.hpp"
#include "tools.hpp"

namespace octocd::cli {

namespace {

bool same_bits(const Aabb& a, const Aabb& b) { return std::memcmp(&a, &b, sizeof(Aabb)) == 0; }

/// A model of box shapes (one per distinct (shape id, local box)) for replaying: no mesh,
/// midphase aabb-only, gravity 0; initial positions `x0`, velocities 0.
std::shared_ptr<Model> box_model(Scene scene, const std::vector<Aabb>& local, const std::vector<std::uint32_t>& shape_id,
                                 const std::vector<std::string>& shape_names, const std::vector<float>& w,
                                 const std::vector<std::string>& group, const std::vector<Vec3>& x0) {
  auto m = std::make_shared<Model>();
  scene.gravity = Vec3{0.0f, 0.0f, 0.0f};
  scene.midphase = MidphaseConfig{};
  scene.midphase.aabb_only = true;
  scene.groups.clear();
  m->scene = std::move(scene);
  std::map<std::tuple<std::uint32_t, float, float, float, float, float, float>, std::uint32_t> index;
  const std::size_t n = local.size();
  m->bodies.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Aabb& b = local[i];
    const auto key = std::make_tuple(shape_id[i], b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z);
    auto it = index.find(key);
    if (it == index.end() || !same_bits(m->shapes[it->second].local, b)) {
      Shape s;
      s.name = (shape_id[i] < shape_names.size() ? shape_names[shape_id[i]] : "shape" + std::to_string(shape_id[i])) +
               " (box)";
      s.local = b;
      it = index.emplace(key, static_cast<std::uint32_t>(m->shapes.size())).first;
      m->shapes.push_back(std::move(s));
    }
    m->bodies[i].shape = it->second;
    m->bodies[i].group = i < group.size() ? group[i] : "";
  }
  m->theta_shape.assign(m->shapes.size(), 0.0f);
  m->initial.x = x0;
  m->initial.v.assign(n, Vec3{});
  m->initial.w = w;
  return m;
}

Vec3 vec3_of(const nlohmann::json& j) {
  return Vec3{j.at(0).get<float>(), j.at(1).get<float>(), j.at(2).get<float>()};
}

}  // namespace

ReplayInput replay_input_from_trace(const std::string& path, int every, int max_frames) {
  TraceReader tr(path);
  // Version 2 (a rotating engine, design.md section 13): replay's input is each state advanced by
  // octocd's translation-only Eq. 2-3 and the local box translated there; a rotating body's
  // world AABB is the bounds of its rotated shape, and such an engine detects at the
  // pre-step pose: these would not be the AABBs its broadphase saw (docs/trace-format.md).
  if (tr.version() == 2)
    throw InputError(fmt::format(
        "{}: version: 2 (a rotating engine's trace); replay cannot replay it: it re-derives each step's world AABBs "
        "as the local box translated to the recorded state advanced by octocd's translation-only Eq. 2-3, but the "
        "bodies of a version 2 trace rotate (their world AABB is the bounds of the rotated shape) and its engine "
        "detects at the pre-step pose, so replay would not feed the AABBs its broadphase saw; allowed: a version 1 "
        "trace of `octocd run` (engine cpu, cuda, or bullet without --rotation); compare version 2 traces with "
        "`octocd compare` and judge them with `octocd validate --trace-in`",
        path));
  const auto need = [&](const char* d, const char* what) {
    if (!tr.has_dataset(d))
      throw InputError(fmt::format("{}: {}: missing; allowed: a trace holding {} (written by `octocd run --trace`, "
                                   "docs/trace-format.md)",
                                   path, d, what));
  };
  need("/bodies/local_aabb_min", "the bodies' local boxes");
  need("/bodies/local_aabb_max", "the bodies' local boxes");
  need("/bodies/inverse_mass", "the bodies' inverse masses");
  need("/bodies/shape_id", "the bodies' shapes");
  need("/states/frame", "the recorded states (positions and velocities every K-th frame)");
  need("/states/position", "the recorded positions");
  need("/states/velocity", "the recorded velocities (replay advances each state by one step)");
  if (!tr.has_attribute("parameters"))
    throw InputError(fmt::format("{}: parameters: missing root attribute; allowed: a trace written by octocd", path));
  nlohmann::json p;
  try {
    p = nlohmann::json::parse(tr.string_attribute("parameters"));
  } catch (const nlohmann::json::exception& e) {
    throw InputError(fmt::format("{}: parameters: not JSON ({})", path, e.what()));
  }

  Scene scene;
  try {
    scene.name = tr.has_attribute("scene_name") ? tr.string_attribute("scene_name") : "trace";
    scene.domain.min = vec3_of(p.at("domain").at("min"));
    scene.domain.max = vec3_of(p.at("domain").at("max"));
    scene.dt = p.at("dt").get<float>();
    scene.broadphase.name = p.at("broadphase").at("name").get<std::string>();
    scene.broadphase.octree_depth = p.at("broadphase").at("octree_depth").get<int>();
    scene.broadphase.cell_size = p.at("broadphase").at("cell_size").get<float>();
  } catch (const nlohmann::json::exception& e) {
    throw InputError(fmt::format("{}: parameters: {}; allowed: the keys of docs/trace-format.md", path, e.what()));
  }
  Vec3 gravity;
  try {
    gravity = vec3_of(p.at("gravity"));
  } catch (const nlohmann::json::exception& e) {
    throw InputError(fmt::format("{}: parameters.gravity: {}", path, e.what()));
  }

  // Values checked for what arithmetic will do with them (docs/trace-format.md, "Security
  // rules and limits"), before any tree is built.
  const auto bad_param = [&](const std::string& key, const std::string& value, const std::string& allowed) {
    throw InputError(fmt::format("{}: parameters.{}: {}; allowed: {}", path, key, value, allowed));
  };
  for (int a = 0; a < 3; ++a) {
    const float lo = scene.domain.min[a], hi = scene.domain.max[a];
    if (!(std::fabs(lo) <= limits::kMaxCoordinate && std::fabs(hi) <= limits::kMaxCoordinate))
      bad_param("domain", fmt::format("axis {}: [{}, {}]", a, lo, hi),
                fmt::format("finite corners, |coordinate| <= {:g} m", limits::kMaxCoordinate));
    if (!(hi - lo >= static_cast<float>(limits::kMinLength)))
      bad_param("domain", fmt::format("axis {}: min {} max {}", a, lo, hi),
                fmt::format("min < max by at least {:g} m on every axis", limits::kMinLength));
  }
  if (!(scene.dt > 0.0f && scene.dt <= static_cast<float>(trace_limits::kMaxDt)))
    bad_param("dt", fmt::format("{}", scene.dt), fmt::format("a time step in (0, {:g}] s", trace_limits::kMaxDt));
  if (!(scene.broadphase.cell_size >= static_cast<float>(limits::kMinLength) &&
        scene.broadphase.cell_size <= static_cast<float>(limits::kMaxLength)))
    bad_param("broadphase.cell_size", fmt::format("{}", scene.broadphase.cell_size),
              fmt::format("[{:g}, {:g}] m", limits::kMinLength, limits::kMaxLength));
  if (scene.broadphase.octree_depth < -1 || scene.broadphase.octree_depth > 10)
    bad_param("broadphase.octree_depth", fmt::format("{}", scene.broadphase.octree_depth), "-1 (auto) or 0..10");
  for (int a = 0; a < 3; ++a)
    if (!(std::fabs(gravity[a]) <= static_cast<float>(limits::kMaxAcceleration)))
      bad_param("gravity", fmt::format("({}, {}, {})", gravity.x, gravity.y, gravity.z),
                fmt::format("finite, |component| <= {:g} m/s^2", limits::kMaxAcceleration));

  const std::vector<Aabb> local = tr.local_boxes();
  const auto n = static_cast<std::int64_t>(local.size());
  const std::vector<float> w = tr.read_f32("/bodies/inverse_mass", n);
  const std::vector<std::uint32_t> shape_id = tr.read_u32("/bodies/shape_id", n);
  const std::vector<std::string> names =
      tr.has_dataset("/bodies/shape_names") ? tr.read_strings("/bodies/shape_names") : std::vector<std::string>{};
  const std::vector<std::string> group =
      tr.has_dataset("/bodies/group") ? tr.read_strings("/bodies/group") : std::vector<std::string>{};

  // Recorded pair counts per frame.
  std::map<std::int64_t, std::int64_t> recorded;
  std::int64_t last_frame = 0;
  if (tr.has_dataset("/frames/frame")) {
    const std::int64_t rows = tr.complete_rows("/frames");
    const auto fr = tr.read_i64("/frames/frame", rows);
    if (!fr.empty()) last_frame = fr.back();
    if (tr.has_dataset("/frames/aabb_pairs")) {
      const auto pc = tr.read_u64("/frames/aabb_pairs", rows);
      for (std::size_t i = 0; i < fr.size(); ++i) recorded[fr[i]] = static_cast<std::int64_t>(pc[i]);
    }
  }

  // Complete rows only: at most the committed_states attribute (docs/trace-format.md).
  const std::int64_t srows = tr.complete_rows("/states");
  const auto sframes = tr.read_i64("/states/frame", srows);
  for (const char* d : {"/states/position", "/states/velocity"}) {
    const auto shape = tr.shape(d);
    if (shape.size() != 3 || static_cast<std::int64_t>(shape[1]) != n || shape[2] != 3)
      throw InputError(fmt::format("{}: {}: shape does not match {} bodies x 3; allowed: states x bodies x 3", path,
                                   d, n));
  }
  for (std::size_t r = 0; r < sframes.size(); ++r)
    if (sframes[r] < 0 || (r > 0 && sframes[r] <= sframes[r - 1]))
      throw InputError(fmt::format("{}: /states/frame: row {} is frame {}{}; allowed: frames >= 0, increasing", path,
                                   r, sframes[r], r > 0 ? fmt::format(" after {}", sframes[r - 1]) : ""));

  ReplayInput in;
  in.source = path;
  const int step = std::max(every, 1);
  for (std::int64_t r = 0; r < srows; r += step) {
    if (sframes[static_cast<std::size_t>(r)] >= last_frame) continue;  // no step followed it
    const auto xf = tr.read_f32_rows("/states/position", r, 1);
    const auto vf = tr.read_f32_rows("/states/velocity", r, 1);
    std::vector<Vec3> x(static_cast<std::size_t>(n));
    for (std::size_t i = 0; i < x.size(); ++i) {
      x[i] = Vec3{xf[3 * i], xf[3 * i + 1], xf[3 * i + 2]};
      Vec3 v{vf[3 * i], vf[3 * i + 1], vf[3 * i + 2]};
      for (int a = 0; a < 3; ++a) {
        const double reach = std::max(std::fabs(local[i].min[a]), std::fabs(local[i].max[a]));
        if (!(std::fabs(x[i][a]) + reach <= trace_limits::kMaxCoordinate))
          throw InputError(fmt::format("{}: /states/position: row {} body {}: {} (+ local extent {}); allowed: "
                                       "|position| + |local extent| <= {:g} m",
                                       path, r, i, x[i][a], reach, trace_limits::kMaxCoordinate));
        if (!(std::fabs(v[a]) <= trace_limits::kMaxSpeed))
          throw InputError(fmt::format("{}: /states/velocity: row {} body {}: {}; allowed: |velocity| <= {:g} m/s", path,
                                       r, i, v[a], trace_limits::kMaxSpeed));
      }
      integrate(x[i], v, w[i], gravity, Vec3{}, scene.dt);  // the engine's next step, Eq. 2-3
    }
    const std::int64_t f = sframes[static_cast<std::size_t>(r)] + 1;
    in.frames.push_back(f);
    in.x.push_back(std::move(x));
    const auto it = recorded.find(f);
    in.recorded_pairs.push_back(it == recorded.end() ? -1 : it->second);
    if (max_frames > 0 && static_cast<int>(in.frames.size()) >= max_frames) break;
  }
  if (in.frames.empty())
    throw InputError(fmt::format("{}: /states: no state row before the last frame ({} rows, last frame {}); "
                                 "allowed: a trace with states recorded before its last step (run with "
                                 "--state-every K smaller than --frames)",
                                 path, srows, last_frame));
  in.model = box_model(scene, local, shape_id, names, w, group, in.x.front());
  return in;
}

ReplayInput replay_input_from_scene(const Scene& scene, int warmup, int frames) {
  const std::shared_ptr<const Model> model = build_model(scene);
  World world(model, make_any_broadphase(scene.broadphase, scene.domain));
  for (int f = 0; f < warmup; ++f) world.step();
  ReplayInput in;
  in.source = scene.path.empty() ? scene.name : scene.path;
  const std::size_t n = world.state().size();
  std::vector<Aabb> local(n);
  std::vector<std::uint32_t> shape_id(n);
  std::vector<std::string> names, group(n);
  for (const Shape& s : model->shapes) names.push_back(s.name);
  for (std::size_t i = 0; i < n; ++i) {
    local[i] = model->local_box(i);
    shape_id[i] = model->bodies[i].shape;
    group[i] = model->bodies[i].group;
  }
  for (int f = 0; f < frames; ++f) {
    std::vector<Vec3> x = world.state().x;
    std::vector<Vec3> v = world.state().v;
    for (std::size_t i = 0; i < n; ++i) integrate(x[i], v[i], world.state().w[i], scene.gravity, Vec3{}, scene.dt);
    world.step();
    for (std::size_t i = 0; i < n; ++i)
      if (!same_bits(translated(local[i], x[i]), world.world_aabbs()[i]))
        throw RuntimeError(fmt::format("replay input of {}: body {} at frame {}: Eq. 2-3 on the recorded state does "
                                       "not give the engine's AABB",
                                       in.source, i, world.frame()));
    in.frames.push_back(world.frame());
    in.x.push_back(std::move(x));
    in.recorded_pairs.push_back(static_cast<std::int64_t>(world.candidate_pairs().size()));
    in.recorded_sets.push_back(world.candidate_pairs());
  }
  Scene s = scene;
  in.model = box_model(s, local, shape_id, names, model->initial.w, group,
                       in.x.empty() ? model->initial.x : in.x.front());
  return in;
}

std::string first_set_difference(const ReplayInput& input, const std::vector<std::vector<Pair>>& a,
                                 const std::vector<std::vector<Pair>>& b) {
  for (std::size_t k = 0; k < std::min(a.size(), b.size()); ++k) {
    if (a[k] == b[k]) continue;
    std::vector<Pair> only_a, only_b;
    std::set_difference(a[k].begin(), a[k].end(), b[k].begin(), b[k].end(), std::back_inserter(only_a));
    std::set_difference(b[k].begin(), b[k].end(), a[k].begin(), a[k].end(), std::back_inserter(only_b));
    const std::int64_t frame = k < input.frames.size() ? input.frames[k] : static_cast<std::int64_t>(k);
    std::string what = fmt::format("frame {}: {} vs {} pairs", frame, a[k].size(), b[k].size());
    if (!only_a.empty()) what += fmt::format(", ({}, {}) only in the first", only_a[0].a, only_a[0].b);
    if (!only_b.empty()) what += fmt::format(", ({}, {}) only in the second", only_b[0].a, only_b[0].b);
    return what;
  }
  return "";
}

ReplayRun replay_broadphase(const ReplayInput& input, const std::string& engine, const std::string& broadphase,
                            int repeat, int warm_replays, double min_ms, const std::function<void()>& tick) {
  ReplayRun r;
  r.engine = engine;
  r.broadphase = broadphase;
  auto model = std::make_shared<Model>(*input.model);
  model->scene.broadphase.name = broadphase;
  std::unique_ptr<Engine> e;
  try {
    e = make_engine(engine, model);
  } catch (const InputError& ex) {
    r.reason = ex.what();
    return r;
  } catch (const RuntimeError& ex) {
    r.reason = ex.what();
    return r;
  }
  r.device = e->device();
  if (e->broadphase_name() != broadphase) {
    r.reason = fmt::format("engine {} runs its own broadphase ({}) whatever is asked", engine, e->broadphase_name());
    return r;
  }
  const bool sets = e->can_record();
  e->set_recording(sets);
  BodyState st;
  st.w = model->initial.w;
  st.v.assign(st.w.size(), Vec3{});
  const std::size_t nf = input.x.size();
  std::vector<std::vector<Pair>> got(nf);
  std::vector<std::uint64_t> counts(nf, 0);
  double pairs = 0.0, candidates = 0.0;
  auto pass = [&](bool timed) {
    double ms = 0.0;
    std::size_t replayed = 0;
    do {  // a timed pass replays the frames until its broadphase time reaches min_ms
      pairs = candidates = 0.0;
      for (std::size_t k = 0; k < nf; ++k) {
        st.x = input.x[k];
        e->set_state(st);
        const FrameMetrics& m = e->step();
        ms += m.stage_ms[static_cast<int>(Stage::Broadphase)];
        pairs += static_cast<double>(m.aabb_pairs);
        candidates += static_cast<double>(m.cell_candidates);
        counts[k] = m.aabb_pairs;
        if (sets) got[k] = e->record().pairs;
        if (tick) tick();
      }
      replayed += nf;
    } while (timed && ms < min_ms && nf > 0);
    if (timed) r.ms.push_back(ms / static_cast<double>(std::max<std::size_t>(replayed, 1)));
  };
  try {
    for (int w = 0; w < warm_replays; ++w) pass(false);
    for (int t = 0; t < std::max(repeat, 1); ++t) pass(true);
  } catch (const InputError& ex) {  // e.g. an engine that cannot take a state from outside
    r.reason = ex.what();
    r.ms.clear();
    return r;
  }
  r.ok = true;
  r.pairs = pairs / static_cast<double>(std::max<std::size_t>(nf, 1));
  r.candidates = candidates / static_cast<double>(std::max<std::size_t>(nf, 1));
  if (!input.recorded_sets.empty() && sets) {
    const std::string d = first_set_difference(input, got, input.recorded_sets);
    r.matches_recorded = d.empty();
    r.recorded_detail = d.empty() ? "pair sets equal the recorded run's on every frame" : d;
  } else {
    r.matches_recorded = true;
    std::size_t checked = 0;
    for (std::size_t k = 0; k < nf; ++k) {
      if (input.recorded_pairs[k] < 0) continue;
      ++checked;
      if (static_cast<std::int64_t>(counts[k]) != input.recorded_pairs[k]) {
        r.matches_recorded = false;
        r.recorded_detail = fmt::format("frame {}: {} pairs, the recorded run had {}", input.frames[k], counts[k],
                                        input.recorded_pairs[k]);
        break;
      }
    }
    if (r.matches_recorded)
      r.recorded_detail = checked ? fmt::format("pair counts equal the recorded ones on {} frames", checked)
                                  : "no recorded pair counts to compare";
  }
  if (sets) r.sets = std::move(got);
  return r;
}

// ---- the command --------------------------------------------------------------------------

CLI::App* add_replay_command(CLI::App& app, ReplayOptions& o) {
  CLI::App* c = add_table_command(app, CommandId::replay);
  c->add_option("trace", o.trace,
                "Trace (.h5) of `octocd run --trace` (needs /bodies, /states and the parameters attribute); format "
                "version 1 only: a version 2 trace (`--engine bullet --rotation`, a rotating engine) is refused "
                "(exit 2): its bodies rotate and its engine detects before integrating, so the translated local "
                "boxes replay feeds are not what its broadphase saw")
      ->required();
  std::string names;
  for (const auto& n : any_engine_broadphase_names()) names += (names.empty() ? "" : ", ") + n;
  names += " (lbvh: --engine cuda only)";
  c->add_option("--broadphase", o.broadphases,
                "Comma-separated broadphases; the first is the reference the others must equal. Names: " + names)
      ->required();
  // The engines that run the scene's broadphase take a recorded state (Engine::set_state).
  std::vector<std::string> replaying;
  for (const EngineInfo& e : engine_infos())
    if (e.uses_scene_broadphase) replaying.push_back(e.name);
  c->add_option("--engine", o.engine,
                "An engine that runs the scene's broadphase: " +
                    engines_with([](const EngineInfo& e) { return e.uses_scene_broadphase; }) +
                    " (cpu: octocd's and the Bullet/FCL broadphases; cuda: the device's)")
      ->check(CLI::IsMember(replaying))
      ->default_val("cpu");
  c->add_option("--repeat", o.repeat, "Timed passes over the frames (>= 1); the median and spread are shown")
      ->check(CLI::PositiveNumber)
      ->default_val(3);
  c->add_option("--warm-replays", o.warm_replays, "Untimed passes first (>= 0)")
      ->check(CLI::NonNegativeNumber)
      ->default_val(1);
  c->add_option("--min-time-ms", o.min_ms,
                "Replay each timed pass again until its broadphase time reaches this (ms; 0 = one replay)")
      ->check(CLI::NonNegativeNumber)
      ->default_val(0.0);
  c->add_option("--every", o.every, "Replay every K-th recorded state (>= 1)")->check(CLI::PositiveNumber)->default_val(1);
  c->add_option("--max-frames", o.max_frames, "Replay at most N frames (0 = all)")
      ->check(CLI::NonNegativeNumber)
      ->default_val(0);
  c->add_option("--json", o.json, "Also write the table as JSON to this file");
  return c;
}

int replay_command(const ReplayOptions& o) {
  if (!o.json.empty()) check_output_file(o.json, "--json");  // before any work (atomic_file.hpp)
  const std::vector<std::string> bps = split_list(o.broadphases);
  if (bps.empty()) throw InputError("--broadphase: empty; allowed: a comma-separated list of broadphase names");
  const auto known = any_engine_broadphase_names();
  for (const auto& b : bps)
    if (std::find(known.begin(), known.end(), b) == known.end()) {
      std::string names;
      for (const auto& n : known) names += (names.empty() ? "" : ", ") + n;
      throw InputError(fmt::format("--broadphase: unknown broadphase '{}'; allowed: {}", b, names));
    }
  const ReplayInput in = replay_input_from_trace(o.trace, o.every, o.max_frames);
  const std::size_t n = in.model->initial.x.size();
  fmt::print("replay {} (scene {}, {} bodies): {} frames, steps {}{}{}\n", o.trace, in.model->scene.name, n,
             in.frames.size(), in.frames.front(), in.frames.size() > 1 ? ", " + std::to_string(in.frames[1]) : "",
             in.frames.size() > 2 ? ", ..." : "");
  fmt::print("input: each recorded state advanced by one step of Eq. 2-3, the AABBs the run's next broadphase saw\n");

  std::vector<ReplayRun> runs;
  for (const auto& b : bps) {
    ReplayRun r = replay_broadphase(in, o.engine, b, o.repeat, o.warm_replays, o.min_ms);
    if (!r.ok) throw InputError(fmt::format("--broadphase: {} on engine {}: {}", b, o.engine, r.reason));
    runs.push_back(std::move(r));
  }
  fmt::print("engine {} on {}; {} untimed and {} timed passes, broadphase-stage ms per frame\n\n", o.engine,
             runs.front().device, o.warm_replays, o.repeat);
  fmt::print("{:<22} {:>10} {:>10} {:>10} {:>12} {:>14}  {:<14} {}\n", "broadphase", "median ms", "min ms", "max ms",
             "pairs/frame", "candidates", "same as first", "recorded counts");
  bool all_ok = true;
  nlohmann::json jr = nlohmann::json::array();
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const ReplayRun& r = runs[i];
    const nlohmann::json s = spread(r.ms);
    std::string same = "(reference)";
    std::string diff;
    if (i > 0) {
      if (!r.sets.empty() && !runs[0].sets.empty()) {
        diff = first_set_difference(in, runs[0].sets, r.sets);
        same = diff.empty() ? "yes" : "NO";
      } else {
        same = r.pairs == runs[0].pairs ? "yes (counts)" : "NO (counts)";
        if (r.pairs != runs[0].pairs) diff = "mean pair counts differ";
      }
    }
    if (!diff.empty() || !r.matches_recorded) all_ok = false;
    fmt::print("{:<22} {:>10.4f} {:>10.4f} {:>10.4f} {:>12.1f} {:>14.1f}  {:<14} {}\n", r.broadphase,
               s.value("median", 0.0), s.value("min", 0.0), s.value("max", 0.0), r.pairs, r.candidates, same,
               r.matches_recorded ? "match" : "DIFFER");
    if (!diff.empty()) fmt::print("  {}: differs from {}: {}\n", r.broadphase, runs[0].broadphase, diff);
    if (!r.matches_recorded) fmt::print("  {}: {}\n", r.broadphase, r.recorded_detail);
    jr.push_back({{"broadphase", r.broadphase},
                  {"engine", r.engine},
                  {"device", r.device},
                  {"ms_per_frame", s},
                  {"pairs", r.pairs},
                  {"candidates", r.candidates},
                  {"same_as_first", diff.empty()},
                  {"difference", diff},
                  {"matches_recorded", r.matches_recorded},
                  {"recorded", r.recorded_detail}});
  }
  fmt::print("\n{}\n", all_ok ? fmt::format("all {} broadphases agree on {} frames and match the recorded pair counts",
                                            runs.size(), in.frames.size())
                              : "REPLAY MISMATCH (a trace of an engine that does not integrate with Eq. 2-3, such as "
                                "bullet, cannot match its recorded counts)");
  if (!o.json.empty()) {
    nlohmann::json j{{"format", "octocd-replay"},
                     {"version", 1},
                     {"trace", o.trace},
                     {"frames", in.frames},
                     {"recorded_pairs", in.recorded_pairs},
                     {"bodies", n},
                     {"machine", machine_description()},
                     {"build", build_description()},
                     {"runs", jr}};
    write_file_atomically(o.json, j.dump(1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n", "--json");
  }
  return all_ok ? 0 : 3;
}

}  // namespace octocd::cli
