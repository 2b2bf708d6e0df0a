// The run request of a process engine (docs/bring-your-engine.md, "The protocol"): read from the
// JSON file octocd writes, checked field by field. A bad request is an Error naming the file,
// the field and what is allowed; nothing in it is trusted before it is checked.
import { readFileSync } from "node:fs";

/// RequestError: a request that breaks the protocol (file, field, allowed range in the message).
export class RequestError extends Error {}

function fail(file, field, problem, allowed) {
  throw new RequestError(`${file}: ${field}: ${problem}; allowed: ${allowed}`);
}

function num(file, field, v, lo = -Infinity, hi = Infinity) {
  if (typeof v !== "number" || !Number.isFinite(v) || v < lo || v > hi) {
    fail(file, field, `${JSON.stringify(v)}`, `a finite number in [${lo}, ${hi}]`);
  }
  return v;
}

function vec(file, field, v, len, lo, hi) {
  if (!Array.isArray(v) || v.length !== len) fail(file, field, `${JSON.stringify(v)?.slice(0, 80)}`, `${len} numbers`);
  return v.map((x, i) => num(file, `${field}[${i}]`, x, lo, hi));
}

const kMaxBodies = 10_000_000;
const kMaxFrames = 100_000_000;

/// Reads and checks a run request (format "octocd-run-request", version 1). Returns the request
/// with numbers checked: bodies (shape "box" with half_extents, or "mesh" with a mesh index),
/// meshes (vertices in the body frame, triangles), frames, dt, gravity, settings (strings).
export function readRequest(file) {
  let text;
  try {
    text = readFileSync(file, "utf8");
  } catch (e) {
    throw new RequestError(`${file}: cannot read the request (${e.code ?? e.message})`);
  }
  let r;
  try {
    r = JSON.parse(text);
  } catch (e) {
    throw new RequestError(`${file}: not JSON (${e.message})`);
  }
  if (r === null || typeof r !== "object") fail(file, "(root)", "not an object", "a JSON object");
  if (r.format !== "octocd-run-request") fail(file, "format", JSON.stringify(r.format), '"octocd-run-request"');
  if (r.version !== 1) fail(file, "version", JSON.stringify(r.version), "1");
  if (typeof r.trace !== "string" || r.trace.length === 0) fail(file, "trace", JSON.stringify(r.trace), "a file path");
  if (!Number.isInteger(r.frames) || r.frames < 0 || r.frames > kMaxFrames) {
    fail(file, "frames", JSON.stringify(r.frames), `an integer in [0, ${kMaxFrames}]`);
  }
  num(file, "dt", r.dt, 1e-9, 10);
  if (!(r.dt > 0)) fail(file, "dt", JSON.stringify(r.dt), "> 0 s");
  vec(file, "gravity", r.gravity, 3, -1e6, 1e6);
  if (typeof r.scene_json !== "string") fail(file, "scene_json", typeof r.scene_json, "a string (the scene JSON)");
  if (typeof r.scene_name !== "string") fail(file, "scene_name", typeof r.scene_name, "a string");
  const settings = r.settings ?? {};
  if (typeof settings !== "object" || Array.isArray(settings)) fail(file, "settings", "not an object", "{KEY: VALUE} strings");
  for (const [k, v] of Object.entries(settings)) {
    if (typeof v !== "string") fail(file, `settings.${k}`, JSON.stringify(v), "a string value");
  }
  r.settings = settings;
  const resp = r.response ?? {};
  r.response = { mu: num(file, "response.mu", resp.mu ?? 0.6, 0, 1e6),
                 restitution: num(file, "response.restitution", resp.restitution ?? 0.5, 0, 1) };
  if (!Array.isArray(r.meshes)) fail(file, "meshes", typeof r.meshes, "an array");
  r.meshes.forEach((m, k) => {
    const f = `meshes[${k}]`;
    if (!Array.isArray(m.vertices) || m.vertices.length < 4) fail(file, `${f}.vertices`, "fewer than 4", "[[x, y, z], ...] (m, body frame)");
    const v = new Float64Array(3 * m.vertices.length);
    m.vertices.forEach((p, i) => vec(file, `${f}.vertices[${i}]`, p, 3, -1e6, 1e6).forEach((x, c) => { v[3 * i + c] = x; }));
    if (!Array.isArray(m.triangles) || m.triangles.length < 1) fail(file, `${f}.triangles`, "empty", "[[i, j, k], ...]");
    const t = new Uint32Array(3 * m.triangles.length);
    const nv = m.vertices.length;
    m.triangles.forEach((tri, i) => {
      if (!Array.isArray(tri) || tri.length !== 3) fail(file, `${f}.triangles[${i}]`, JSON.stringify(tri), "3 vertex indices");
      tri.forEach((x, c) => {
        if (!Number.isInteger(x) || x < 0 || x >= nv) fail(file, `${f}.triangles[${i}]`, JSON.stringify(tri), `indices in [0, ${nv - 1}]`);
        t[3 * i + c] = x;
      });
    });
    m.vertexArray = v;
    m.triangleArray = t;
  });
  if (!Array.isArray(r.bodies) || r.bodies.length < 1 || r.bodies.length > kMaxBodies) {
    fail(file, "bodies", "not an array of 1 or more", `1 .. ${kMaxBodies} bodies`);
  }
  r.bodies.forEach((b, i) => {
    const f = `bodies[${i}]`;
    if (typeof b.group !== "string") fail(file, `${f}.group`, JSON.stringify(b.group), "a string");
    if (b.shape === "box") {
      vec(file, `${f}.half_extents`, b.half_extents, 3, 1e-9, 1e6);
    } else if (b.shape === "mesh") {
      if (!Number.isInteger(b.mesh) || b.mesh < 0 || b.mesh >= r.meshes.length) {
        fail(file, `${f}.mesh`, JSON.stringify(b.mesh), `an index in [0, ${r.meshes.length - 1}]`);
      }
    } else {
      fail(file, `${f}.shape`, JSON.stringify(b.shape), '"box" or "mesh"');
    }
    if (typeof b.static !== "boolean") fail(file, `${f}.static`, JSON.stringify(b.static), "true or false");
    if (b.static) {
      b.mass = 0;
    } else {
      num(file, `${f}.mass`, b.mass, 1e-9, 1e12);
      if (!Array.isArray(b.inertia) || b.inertia.length !== 3) fail(file, `${f}.inertia`, "not 3 x 3", "a 3 x 3 tensor (kg m^2)");
      b.inertia.forEach((row, k) => vec(file, `${f}.inertia[${k}]`, row, 3, -1e12, 1e12));
    }
    vec(file, `${f}.local_aabb_min`, b.local_aabb_min, 3, -1e6, 1e6);
    vec(file, `${f}.local_aabb_max`, b.local_aabb_max, 3, -1e6, 1e6);
    vec(file, `${f}.position`, b.position, 3, -1e9, 1e9);
    const q = vec(file, `${f}.orientation`, b.orientation, 4, -2, 2);
    const nq = Math.hypot(...q);
    if (Math.abs(nq - 1) > 1e-3) fail(file, `${f}.orientation`, `|q| = ${nq}`, "a unit quaternion (w, x, y, z) within 1e-3");
    vec(file, `${f}.velocity`, b.velocity, 3, -1e6, 1e6);
    vec(file, `${f}.angular_velocity`, b.angular_velocity, 3, -1e6, 1e6);
    num(file, `${f}.friction`, b.friction ?? r.response.mu, 0, 1e6);
    num(file, `${f}.restitution`, b.restitution ?? r.response.restitution, 0, 1);
    b.friction = b.friction ?? r.response.mu;
    b.restitution = b.restitution ?? r.response.restitution;
  });
  r.file = file;
  return r;
}

/// The engine's settings from request.settings: `spec` maps each KEY the engine accepts to
/// {def, parse(value) -> value or undefined, allowed}. An unknown KEY or a bad VALUE is an Error
/// naming the key and what is allowed.
export function parseSettings(req, spec) {
  const out = {};
  for (const [k, s] of Object.entries(spec)) out[k] = s.def;
  for (const [k, v] of Object.entries(req.settings)) {
    const s = spec[k];
    if (!s) fail(req.file, `settings.${k}`, "unknown", `one of ${Object.keys(spec).join(", ")}`);
    const x = s.parse(v);
    if (x === undefined) fail(req.file, `settings.${k}`, JSON.stringify(v), s.allowed);
    out[k] = x;
  }
  return out;
}

/// A setting parser: an integer in [lo, hi].
export function intIn(lo, hi) {
  return (v) => (/^-?\d+$/.test(v) && +v >= lo && +v <= hi ? +v : undefined);
}
