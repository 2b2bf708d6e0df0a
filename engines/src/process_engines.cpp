// Process engines (process_engines.hpp): the engines files, read strictly; availability;
// settings items; the run request.
#include "octocd/process_engines.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

#include <fmt/format.h>

#include "child_process.hpp"
#include "octocd/atomic_file.hpp"
#include "octocd/convex_hull.hpp"
#include "octocd/error.hpp"
#include "octocd/external_trace.hpp"
#include "octocd/json_fields.hpp"
#include "octocd/json_strict.hpp"
#include "octocd/names.hpp"
#include "octocd/shared_files.hpp"
#include "octocd/text.hpp"

namespace octocd {

namespace fs = std::filesystem;

namespace {

/// Largest engines file (bytes).
constexpr std::uintmax_t kMaxEnginesFileBytes = 1 << 20;
/// Most engines in one file, items of a command, settings keys.
constexpr std::size_t kMaxEngines = 256, kMaxItems = 64, kMaxKeys = 64;
/// Wall-time bound of a check command (s).
constexpr double kCheckTimeoutS = 30.0;
/// Most check commands check_process_engines runs at once (each a process that mostly waits).
constexpr std::size_t kMostChecksAtOnce = 32;

std::mutex g_mutex;
std::string g_user_file;  // set_engines_file
bool g_loaded = false;
std::vector<ProcessEngineSpec> g_engines;
std::vector<std::string> g_files;
std::map<std::string, std::string> g_unavailable;  // name -> why ("" available), cached

/// The engines files to read, in order (those that exist).
std::vector<std::string> engines_file_candidates(const std::string& user_file) {
  std::vector<std::string> files;
  std::error_code ec;
  const fs::path shipped = fs::path(shared_dir()) / "engines.json";
  if (fs::is_regular_file(shipped, ec)) {
    files.push_back(shipped.string());
  } else if (fs::is_regular_file(OCTOCD_BUILD_ENGINES_FILE, ec)) {
    files.push_back(OCTOCD_BUILD_ENGINES_FILE);
  }
  const char* xdg = std::getenv("XDG_CONFIG_HOME");
  const char* home = std::getenv("HOME");
  std::optional<fs::path> config;
  if (xdg && *xdg) config = fs::path(xdg) / "octocd" / "engines.json";
  else if (home && *home) config = fs::path(home) / ".config" / "octocd" / "engines.json";
  if (config && fs::exists(*config, ec)) files.push_back(config->string());
  if (!user_file.empty()) files.push_back(user_file);
  return files;
}

/// A command item that names a file: resolved against `folder` when it exists there.
std::string resolve_item(const std::string& item, const fs::path& folder) {
  if (item.empty() || item[0] == '-') return item;
  const fs::path p(item);
  if (p.is_absolute()) return item;
  std::error_code ec;
  const fs::path there = folder / p;
  if (fs::is_regular_file(there, ec)) return fs::absolute(there, ec).lexically_normal().string();
  return item;
}

/// Whether item `i` of a command reads as a file name: a script's name (`eng(1).py`), or a
/// path holding no character of code. Never an option, the code an interpreter's code option
/// takes (`python3 -c CODE`, `node -e CODE`, `perl -E CODE`), or an item holding a line
/// break, a quote or a shell character (`;`, `$`, `|`, ...); a path holding a bracket, `*`,
/// `?`, `!` or a backslash is code too: `print(1/1)` is code, not a missing file.
bool names_a_file(const std::vector<std::string>& argv, std::size_t i) {
  const std::string& item = argv[i];
  if (item.empty() || item[0] == '-') return false;
  if (i > 0)
    for (const char* code_option : {"-c", "-e", "-E", "-p", "--eval", "--print"})
      if (argv[i - 1] == code_option) return false;
  if (item.find_first_of("\n\r\t;'\"`$|&<>") != std::string::npos) return false;
  for (const char* ext : {".js", ".mjs", ".cjs", ".py", ".rb", ".lua", ".jar", ".wasm", ".exe"})
    if (item.size() > std::strlen(ext) && item.compare(item.size() - std::strlen(ext), std::string::npos, ext) == 0)
      return true;
  return item.find('/') != std::string::npos && item.find_first_of("()[]{}*?!\\") == std::string::npos;
}

std::vector<std::string> read_argv(const JsonFields& f, const nlohmann::json& v, const std::string& field,
                                   const fs::path& folder) {
  const std::string allowed =
      "an argument vector: a JSON array of 1 to 64 non-empty strings (e.g. [\"node\", \"engine.js\"]), never a shell "
      "string";
  if (v.is_string())
    f.fail(field, fmt::format("a string ({}): a shell command line is never run", v.dump()), allowed);
  if (!v.is_array() || v.empty()) f.fail(field, json_type_text(v), allowed);
  f.array(v, field, kMaxItems);
  std::vector<std::string> argv;
  for (std::size_t i = 0; i < v.size(); ++i) {
    const std::string where = fmt::format("{}[{}]", field, i);
    std::string item = f.text(v[i], where, 4096);
    if (item.empty()) f.fail(where, "an empty string", allowed);
    if (item.find('\0') != std::string::npos) f.fail(where, "a NUL byte", allowed);
    if (i == 0 && item.find_first_of(" \t\n;|&$`<>()*?'\"\\") != std::string::npos)
      f.fail(where, fmt::format("'{}' reads as a shell command line", item),
             "a program's name or path alone, its arguments as further items");
    // argv[0]: a name looked up on PATH, or a path (a relative one against the engines
    // file's folder, where the other items are resolved too).
    if (i == 0 && item.find('/') != std::string::npos && item[0] != '/')
      argv.push_back((folder / item).lexically_normal().string());
    else
      argv.push_back(i == 0 ? item : resolve_item(item, folder));
  }
  return argv;
}

}  // namespace

void set_engines_file(const std::string& path) {
  const std::lock_guard<std::mutex> lock(g_mutex);
  if (g_loaded && path != g_user_file)
    throw RuntimeError(fmt::format("engines file '{}': the engines files were read already (with '{}'); allowed: one "
                                   "engines file per process, given before the first engine is looked up",
                                   path, g_user_file));
  g_user_file = path;
}

std::vector<std::string> engines_files_read() {
  const std::lock_guard<std::mutex> lock(g_mutex);
  return g_files;
}

std::vector<ProcessEngineSpec> read_engines_file(const std::string& path, const std::vector<std::string>& builtin) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec))
    throw InputError(fmt::format("{}: not a readable file; allowed: an engines file (JSON, docs/bring-your-engine.md)",
                                 path));
  if (fs::file_size(path, ec) > kMaxEnginesFileBytes)
    throw InputError(fmt::format("{}: larger than {} bytes; allowed: an engines file of at most 1 MiB", path,
                                 kMaxEnginesFileBytes));
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  if (!in.good() && !in.eof()) throw InputError(fmt::format("{}: cannot be read", path));
  const nlohmann::json doc = parse_json_strict(ss.str(), path);
  const JsonFields f(path);
  const fs::path folder = fs::absolute(fs::path(path), ec).parent_path();
  f.object(doc, "(root)");
  for (const auto& [key, value] : doc.items()) {
    (void)value;
    if (key != "format" && key != "version" && key != "engines")
      f.fail(key, "an unknown field", "format, version, engines");
  }
  f.one_of(f.member(doc, "(root)", "format", "\"octocd-engines\""), "format", {"octocd-engines"});
  f.integer(f.member(doc, "(root)", "version", "1"), "version", 1, 1);
  const nlohmann::json& list = f.array(f.member(doc, "(root)", "engines", "an array of engines"), "engines", kMaxEngines);
  static const std::regex kName("[a-z0-9_-]{1,32}");
  static const std::regex kKey("[A-Za-z0-9_.-]{1,64}");
  static const std::vector<std::string> kFields{"name",     "description", "command",   "check",
                                                "rotates",  "geometries",  "settings",  "timeout_s",
                                                "max_trace_bytes"};
  std::vector<ProcessEngineSpec> out;
  std::set<std::string> names;
  for (std::size_t i = 0; i < list.size(); ++i) {
    const std::string at = fmt::format("engines[{}]", i);
    const nlohmann::json& e = f.object(list[i], at);
    for (const auto& [key, value] : e.items()) {
      (void)value;
      if (std::find(kFields.begin(), kFields.end(), key) == kFields.end())
        f.fail(at + "." + key, "an unknown field", join_names(kFields));
    }
    ProcessEngineSpec s;
    s.file = path;
    const std::string name = f.text(f.member(e, at, "name", "a name of [a-z0-9_-]{1,32}"), at + ".name", 32);
    if (!std::regex_match(name, kName))
      f.fail(at + ".name", fmt::format("'{}'", name), "a name of [a-z0-9_-]{1,32}");
    if (std::find(builtin.begin(), builtin.end(), name) != builtin.end())
      f.fail(at + ".name", fmt::format("'{}' is a built-in engine", name),
             "a name no built-in engine has (built in: " + join_names(builtin) + ")");
    if (!names.insert(name).second) f.fail(at + ".name", fmt::format("'{}' twice in this file", name), "each name once");
    s.info.name = name;
    s.info.description = e.contains("description") ? f.text(e["description"], at + ".description", 1000)
                                                   : fmt::format("a process engine ({})", path);
    s.command = read_argv(f, f.member(e, at, "command", "an argument vector"), at + ".command", folder);
    if (e.contains("check")) s.check = read_argv(f, e["check"], at + ".check", folder);
    s.info.rotates = e.contains("rotates") ? f.boolean(e["rotates"], at + ".rotates") : true;
    s.info.geometries = {"hull"};
    if (e.contains("geometries")) {
      const nlohmann::json& g = f.array(e["geometries"], at + ".geometries", 3);
      if (g.empty()) f.fail(at + ".geometries", "an empty array", "one or more of mesh, hull, box");
      s.info.geometries.clear();
      for (std::size_t k = 0; k < g.size(); ++k)
        s.info.geometries.push_back(f.one_of(g[k], fmt::format("{}.geometries[{}]", at, k), {"mesh", "hull", "box"}));
    }
    if (e.contains("settings")) {
      const nlohmann::json& keys = f.array(e["settings"], at + ".settings", kMaxKeys);
      for (std::size_t k = 0; k < keys.size(); ++k) {
        const std::string where = fmt::format("{}.settings[{}]", at, k);
        const std::string key = f.text(keys[k], where, 64);
        if (!std::regex_match(key, kKey)) f.fail(where, fmt::format("'{}'", key), "a key of [A-Za-z0-9_.-]{1,64}");
        if (std::find(s.settings.begin(), s.settings.end(), key) != s.settings.end())
          f.fail(where, fmt::format("'{}' twice", key), "each key once");
        s.settings.push_back(key);
      }
    }
    if (e.contains("timeout_s")) {
      const double t = f.number_or_null(e["timeout_s"], at + ".timeout_s", 1e-3, 7 * 86400.0);
      if (!(t > 0)) f.fail(at + ".timeout_s", "null", "a number of seconds in [0.001, 604800]");
      s.timeout_s = t;
    }
    if (e.contains("max_trace_bytes"))
      s.max_trace_bytes = f.count(e["max_trace_bytes"], at + ".max_trace_bytes", 1ull << 50);
    s.info.records_every_step = false;  // judged through its trace
    s.info.own_broadphase = name;
    s.info.own_broadphase_class = fmt::format("engine {}'s own broadphase (a process engine)", name);
    s.info.no_midphase_reason = fmt::format("{} is a process engine: it runs its own collision detection", name);
    s.info.command = s.command;
    out.push_back(std::move(s));
  }
  return out;
}

const std::vector<ProcessEngineSpec>& process_engines(const std::vector<std::string>& builtin) {
  const std::lock_guard<std::mutex> lock(g_mutex);
  if (g_loaded) return g_engines;
  std::vector<ProcessEngineSpec> all;
  std::vector<std::string> files = engines_file_candidates(g_user_file);
  for (const std::string& file : files)
    for (ProcessEngineSpec& s : read_engines_file(file, builtin)) {
      auto same = std::find_if(all.begin(), all.end(), [&](const ProcessEngineSpec& x) { return x.info.name == s.info.name; });
      if (same != all.end()) *same = std::move(s);
      else all.push_back(std::move(s));
    }
  g_engines = std::move(all);
  g_files = std::move(files);
  g_loaded = true;
  return g_engines;
}

const ProcessEngineSpec* find_process_engine(const std::string& name) {
  const std::lock_guard<std::mutex> lock(g_mutex);
  for (const ProcessEngineSpec& s : g_engines)
    if (s.info.name == name) return &s;
  return nullptr;
}

namespace {

using CheckClock = std::chrono::steady_clock;

/// process_engine_unavailable with its check bounded by `deadline` as well as kCheckTimeoutS
/// (the shorter), cached. A check that cannot start before `deadline` is not run, and says so.
std::string unavailable_by(const ProcessEngineSpec& spec, CheckClock::time_point deadline, double bound_s) {
  {
    const std::lock_guard<std::mutex> lock(g_mutex);
    if (const auto it = g_unavailable.find(spec.info.name); it != g_unavailable.end()) return it->second;
  }
  std::string why;
  try {
    const fs::path folder = fs::path(spec.file).parent_path();
    auto missing = [&](const std::vector<std::string>& argv, const char* what) -> std::string {
      if (const std::string not_runnable = process_detail::why_not_runnable(argv[0]); !not_runnable.empty())
        return fmt::format("{} '{}' {} ({})", what, printable(argv[0]), not_runnable, spec.file);
      for (std::size_t i = 1; i < argv.size(); ++i) {
        if (!names_a_file(argv, i)) continue;
        std::error_code ec;
        const fs::path p = fs::path(argv[i]).is_absolute() ? fs::path(argv[i]) : folder / argv[i];
        if (!fs::exists(p, ec)) return fmt::format("{} file '{}' is missing ({})", what, printable(p.string()), spec.file);
        // Examined with stat, never opened: a program reading a FIFO blocks until its bound,
        // a device may never end. A folder may be an argument (a package, a data folder).
        struct stat st {};
        if (::stat(p.c_str(), &st) == 0 && !S_ISREG(st.st_mode) && !S_ISDIR(st.st_mode))
          return fmt::format("{} item '{}' is not a regular file ({}); not run: a program reading it would block or "
                             "never end; allowed: a regular file or a folder ({})",
                             what, printable(p.string()), file_type_word(st.st_mode), spec.file);
      }
      return "";
    };
    why = missing(spec.command, "command");
    if (why.empty() && !spec.check.empty()) why = missing(spec.check, "check");
    if (why.empty() && !spec.check.empty()) {
      process_detail::ChildRun run;
      run.argv = spec.check;
      run.argv[0] = process_detail::find_on_path(spec.check[0]);
      run.cwd = folder.string();
      run.timeout_s = std::min(kCheckTimeoutS, std::chrono::duration<double>(deadline - CheckClock::now()).count());
      run.timeout_setting = "the checks' overall bound (octocd engines --check-timeout)";
      if (run.timeout_s <= 0.0) {
        why = fmt::format("its check ({}) was not run: the checks' overall bound of {:g} s had passed",
                          printable(join_names(spec.check, " ")), bound_s);
      } else {
        const process_detail::ChildOutcome o = process_detail::run_child(run);
        if (o.end == process_detail::ChildOutcome::End::TimedOut)
          why = fmt::format("its check ({}) timed out: it ran past {:.3g} s (the checks' bound, {:g} s for all at "
                            "once) and was stopped{}",
                            printable(join_names(spec.check, " ")), run.timeout_s, bound_s,
                            process_detail::output_tail(o));
        else if (o.end != process_detail::ChildOutcome::End::Exited || o.code != 0)
          why = fmt::format("its check ({}) {}{}", printable(join_names(spec.check, " ")), process_detail::describe(o),
                            process_detail::output_tail(o));
      }
    }
  } catch (const std::exception& e) {
    why = e.what();
  }
  const std::lock_guard<std::mutex> lock(g_mutex);
  g_unavailable[spec.info.name] = why;
  return why;
}

}  // namespace

std::string process_engine_unavailable(const ProcessEngineSpec& spec) {
  return unavailable_by(spec, CheckClock::now() + std::chrono::duration_cast<CheckClock::duration>(
                                                      std::chrono::duration<double>(kCheckTimeoutS)),
                        kCheckTimeoutS);
}

void check_process_engines(const std::vector<ProcessEngineSpec>& specs, double bound_s) {
  if (!(bound_s > 0.0) || !(bound_s <= kCheckTimeoutS))
    throw InputError(fmt::format("the checks' bound: {:g} s; allowed: (0, {:g}] s", bound_s, kCheckTimeoutS));
  const auto deadline =
      CheckClock::now() + std::chrono::duration_cast<CheckClock::duration>(std::chrono::duration<double>(bound_s));
  std::atomic<std::size_t> next{0};
  const auto work = [&] {
    for (std::size_t i = next++; i < specs.size(); i = next++) (void)unavailable_by(specs[i], deadline, bound_s);
  };
  std::vector<std::thread> team;
  const std::size_t n = std::min(specs.size(), kMostChecksAtOnce);
  for (std::size_t t = 1; t < n; ++t) team.emplace_back(work);
  work();
  for (std::thread& t : team) t.join();
}

void check_process_settings(const ProcessEngineSpec& spec, const std::vector<std::string>& items,
                            const std::string& where) {
  const std::string keys = spec.settings.empty() ? "none (this engine has no settings)" : join_names(spec.settings);
  for (const std::string& item : items) {
    const auto eq = item.find('=');
    if (eq == std::string::npos || eq == 0)
      throw InputError(fmt::format("{}: '{}' is not KEY=VALUE; allowed keys: {}", where, item, keys));
    const std::string key = item.substr(0, eq);
    if (std::find(spec.settings.begin(), spec.settings.end(), key) == spec.settings.end())
      throw InputError(fmt::format("{}: unknown setting '{}' of process engine {} ({}); allowed keys: {}", where, key,
                                   spec.info.name, spec.file, keys));
  }
}

namespace {

nlohmann::json vec(const Vec3& v) { return nlohmann::json::array({v.x, v.y, v.z}); }

}  // namespace

nlohmann::ordered_json process_request(const ProcessEngineSpec& spec, const Model& model, std::int64_t frames,
                                       const std::string& trace, const std::vector<std::string>& items) {
  const Scene& scene = model.scene;
  nlohmann::ordered_json r;
  r["format"] = "octocd-run-request";
  r["version"] = 1;
  r["engine"] = spec.info.name;
  r["trace"] = trace;
  r["frames"] = frames;
  r["dt"] = scene.dt;
  r["gravity"] = vec(scene.gravity);
  r["rotation"] = spec.info.rotates || scene_rotates(scene);
  nlohmann::ordered_json settings = nlohmann::ordered_json::object();
  for (const std::string& item : items) {
    const auto eq = item.find('=');
    settings[item.substr(0, eq)] = item.substr(eq + 1);
  }
  r["settings"] = settings;
  r["scene_name"] = scene.name;
  r["scene_json"] = utf8_replaced(scene.json);
  r["response"] = {{"mu", scene.response.mu_static}, {"restitution", scene.response.restitution}};
  // Meshes: one per mesh shape, in the body frame (its origin the centre of the shape's
  // local box: the body's position), with the mass properties of its convex hull.
  std::vector<int> mesh_of(model.shapes.size(), -1);
  std::vector<std::optional<HullMassProperties>> hull_mass(model.shapes.size());
  nlohmann::ordered_json meshes = nlohmann::ordered_json::array();
  std::map<std::string, std::string> files;  // group name -> the mesh file it resolved to
  for (const GroupSpec& g : scene.groups)
    if (!g.shape.mesh_path.empty()) files[g.name] = fs::absolute(g.shape.mesh_path).lexically_normal().string();
  for (std::size_t i = 0; i < model.bodies.size(); ++i) {
    const std::uint32_t k = model.bodies[i].shape;
    const Shape& s = model.shapes[k];
    if (!s.mesh || mesh_of[k] >= 0) continue;
    const Vec3 centre = 0.5f * (s.local.min + s.local.max);
    nlohmann::ordered_json m;
    m["name"] = s.name;
    const auto file = files.find(model.bodies[i].group);
    m["file"] = file == files.end() ? "" : file->second;
    nlohmann::json vs = nlohmann::json::array(), ts = nlohmann::json::array();
    for (const Vec3& v : s.mesh->vertices) vs.push_back(vec(v - centre));
    for (const auto& t : s.mesh->triangles) ts.push_back({t[0], t[1], t[2]});
    m["vertices"] = std::move(vs);
    m["triangles"] = std::move(ts);
    mesh_of[k] = static_cast<int>(meshes.size());
    meshes.push_back(std::move(m));
  }
  r["meshes"] = std::move(meshes);
  nlohmann::ordered_json bodies = nlohmann::ordered_json::array();
  const BodyState& x0 = model.initial;
  for (std::size_t i = 0; i < model.bodies.size(); ++i) {
    const std::uint32_t k = model.bodies[i].shape;
    const Shape& s = model.shapes[k];
    const Vec3 centre = 0.5f * (s.local.min + s.local.max);
    const float w = x0.w[i];
    nlohmann::ordered_json b;
    b["group"] = model.bodies[i].group;
    if (s.mesh) {
      b["shape"] = "mesh";
      b["mesh"] = mesh_of[k];
    } else {
      b["shape"] = "box";
      b["half_extents"] = vec(0.5f * (s.local.max - s.local.min));
    }
    b["static"] = !(w > 0.0f);
    b["mass"] = w > 0.0f ? 1.0 / static_cast<double>(w) : 0.0;
    // Inertia about the body origin: a box's (box_inertia), a mesh's convex hull of uniform
    // density (hull_mass_properties scaled by mass / volume), zeros when static.
    std::array<double, 9> inertia{};
    if (w > 0.0f) {
      if (!s.mesh) {
        inertia = box_inertia(s.local, w);
      } else {
        if (!hull_mass[k]) {
          std::vector<Vec3> pts(s.mesh->vertices);
          for (Vec3& p : pts) p -= centre;
          hull_mass[k] = hull_mass_properties(convex_hull(pts, s.name));
        }
        const double density = (1.0 / static_cast<double>(w)) / hull_mass[k]->volume;
        for (std::size_t c = 0; c < 9; ++c) inertia[c] = density * hull_mass[k]->inertia_origin[c];
      }
    }
    b["inertia"] = {{inertia[0], inertia[1], inertia[2]}, {inertia[3], inertia[4], inertia[5]},
                    {inertia[6], inertia[7], inertia[8]}};
    b["local_aabb_min"] = vec(s.local.min - centre);
    b["local_aabb_max"] = vec(s.local.max - centre);
    b["position"] = vec(x0.x[i]);
    const Quat q = i < x0.q.size() ? x0.q[i] : Quat{};
    b["orientation"] = {q.w, q.x, q.y, q.z};
    b["velocity"] = vec(x0.v[i]);
    b["angular_velocity"] = vec(i < x0.omega.size() ? x0.omega[i] : Vec3{});
    b["friction"] = scene.response.mu_static;
    b["restitution"] = scene.response.restitution;
    bodies.push_back(std::move(b));
  }
  r["bodies"] = std::move(bodies);
  return r;
}

}  // namespace octocd
