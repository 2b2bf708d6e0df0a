// The version 2 trace a process engine writes (docs/trace-format.md, "External traces, version
// 2"), with h5wasm: every state row 0..frames, the contact rows of every frame (CSR), the bodies
// in the request's order, the scene verbatim and the engine's declarations. Rows are buffered
// and appended in batches to extendable datasets; the file is written as TRACE.partial and
// renamed onto TRACE when it is closed, so a killed engine never leaves a half trace there.
import h5wasm from "h5wasm/node";
import { renameSync, rmSync } from "node:fs";

const kBatchBytes = 16 << 20;  // buffered rows written once they hold this much

/// An appendable dataset of rows of `rowShape` (a typed-array constructor `Type`).
class Column {
  constructor(group, name, Type, rowShape, chunkRows) {
    this.Type = Type;
    this.rowShape = rowShape;
    this.rowLen = rowShape.reduce((a, b) => a * b, 1);
    this.rows = 0;
    this.buf = new Type(Math.max(this.rowLen * 1024, 1));
    this.used = 0;
    this.ds = group.create_dataset({ name, data: new Type(0), shape: [0, ...rowShape], maxshape: [null, ...rowShape],
                                     chunks: [chunkRows, ...rowShape] });
  }
  push(values) {  // one row or several (a multiple of rowLen values)
    if (this.used + values.length > this.buf.length) {
      const grown = new this.Type(Math.max(2 * this.buf.length, this.used + values.length));
      grown.set(this.buf.subarray(0, this.used));
      this.buf = grown;
    }
    this.buf.set(values, this.used);
    this.used += values.length;
  }
  get bytes() { return this.used * this.Type.BYTES_PER_ELEMENT; }
  flush() {
    if (this.used === 0) return;
    const add = this.used / this.rowLen;
    this.ds.resize([this.rows + add, ...this.rowShape]);
    const sel = [[this.rows, this.rows + add], ...this.rowShape.map(() => [])];
    this.ds.write_slice(sel, this.buf.subarray(0, this.used));
    this.rows += add;
    this.used = 0;
  }
}

/// Root attribute values: {value, type} with type "str", "i32", "f64" or "f64[]".
export const str = (value) => ({ value, type: "str" });
export const i32 = (value) => ({ value, type: "i32" });
export const f64 = (value) => ({ value, type: "f64" });

function setAttr(obj, name, a) {
  if (a.type === "str") obj.create_attribute(name, String(a.value));
  else if (a.type === "i32") obj.create_attribute(name, new Int32Array([a.value]), [], "<i");
  else if (a.type === "f64") obj.create_attribute(name, new Float64Array([a.value]), [], "<d");
  else if (a.type === "f64[]") obj.create_attribute(name, Float64Array.from(a.value), [a.value.length], "<d");
  else throw new Error(`attribute ${name}: unknown type ${a.type}`);
}

/// The trace of one run. `req`: the checked request; `engine`: the engine's name and version
/// ("rapier 0.21.0"); `attrs`: its declarations ({name: str(..)|i32(..)|f64(..)}); `bodyData`:
/// extra /bodies datasets ({name: {strings: [...]} or {f64: Float64Array}}); `jt3`: whether the
/// rows carry friction vectors (/contacts/jt3).
export class TraceWriter {
  /// Loads h5wasm (the `--check` of every engine).
  static async ready() { await h5wasm.ready; }

  static async open(req, engine, attrs, { bodyData = {}, jt3 = false } = {}) {
    await h5wasm.ready;
    return new TraceWriter(req, engine, attrs, bodyData, jt3);
  }

  constructor(req, engine, attrs, bodyData, jt3) {
    this.path = req.trace;
    this.partial = `${req.trace}.partial`;
    rmSync(this.partial, { force: true });
    const n = req.bodies.length;
    this.n = n;
    const f = new h5wasm.File(this.partial, "w");
    this.f = f;
    const root = {
      format: str("octocd-trace"), version: i32(2), engine: str(engine), scene: str(req.scene_json),
      scene_name: str(req.scene_name), dt: f64(req.dt), gravity: { value: req.gravity, type: "f64[]" },
      body_count: i32(n), state_every: i32(1), detection: str("pre-step"), contact_geometry: str("shape"),
      mu: f64(req.response.mu), restitution: f64(req.response.restitution), ...attrs,
    };
    for (const [k, a] of Object.entries(root)) setAttr(f, k, a);
    const b = f.create_group("bodies");
    const lo = new Float64Array(3 * n), hi = new Float64Array(3 * n), im = new Float64Array(n);
    const inertia = new Float64Array(9 * n), fr = new Float64Array(n), re = new Float64Array(n);
    const groupNames = [], groupId = new Int32Array(n);
    req.bodies.forEach((body, i) => {
      lo.set(body.local_aabb_min, 3 * i);
      hi.set(body.local_aabb_max, 3 * i);
      im[i] = body.static ? 0 : 1 / body.mass;
      if (!body.static) inertia.set(body.inertia.flat(), 9 * i);
      fr[i] = body.friction;
      re[i] = body.restitution;
      let g = groupNames.indexOf(body.group);
      if (g < 0) { groupNames.push(body.group); g = groupNames.length - 1; }
      groupId[i] = g;
    });
    b.create_dataset({ name: "local_aabb_min", data: lo, shape: [n, 3] });
    b.create_dataset({ name: "local_aabb_max", data: hi, shape: [n, 3] });
    b.create_dataset({ name: "inverse_mass", data: im, shape: [n] });
    b.create_dataset({ name: "inertia", data: inertia, shape: [n, 3, 3] });
    b.create_dataset({ name: "friction", data: fr, shape: [n] });
    b.create_dataset({ name: "restitution", data: re, shape: [n] });
    b.create_dataset({ name: "group", data: req.bodies.map((x) => x.group) });
    b.create_dataset({ name: "group_names", data: groupNames });
    b.create_dataset({ name: "group_id", data: groupId, shape: [n] });
    for (const [k, d] of Object.entries(bodyData)) {
      if (d.strings) b.create_dataset({ name: k, data: d.strings });
      else b.create_dataset({ name: k, data: d.f64, shape: [n] });
    }
    const s = f.create_group("states");
    const chunk = Math.max(1, Math.min(64, Math.floor((1 << 20) / (32 * n))));
    this.sFrame = new Column(s, "frame", BigInt64Array, [], 1024);
    this.sPos = new Column(s, "position", Float64Array, [n, 3], chunk);
    this.sVel = new Column(s, "velocity", Float64Array, [n, 3], chunk);
    this.sQ = new Column(s, "orientation", Float64Array, [n, 4], chunk);
    this.sW = new Column(s, "angular_velocity", Float64Array, [n, 3], chunk);
    const c = f.create_group("contacts");
    this.cOffsets = new Column(c, "offsets", BigInt64Array, [], 1024);
    this.cFrame = new Column(c, "frame", BigInt64Array, [], 1024);
    this.cPair = new Column(c, "pair", Uint32Array, [2], 4096);
    this.cNormal = new Column(c, "normal", Float64Array, [3], 4096);
    this.cPoint = new Column(c, "point", Float64Array, [3], 4096);
    this.cDepth = new Column(c, "depth", Float64Array, [], 4096);
    this.cJn = new Column(c, "jn", Float64Array, [], 4096);
    this.cJt = new Column(c, "jt", Float64Array, [], 4096);
    this.cJt3 = jt3 ? new Column(c, "jt3", Float64Array, [3], 4096) : null;
    this.contactRows = 0;
    this.cOffsets.push([0n]);
    this.columns = [this.sFrame, this.sPos, this.sVel, this.sQ, this.sW, this.cOffsets, this.cFrame, this.cPair,
                    this.cNormal, this.cPoint, this.cDepth, this.cJn, this.cJt, ...(this.cJt3 ? [this.cJt3] : [])];
  }

  /// Appends state row `frame` (Float64Arrays: n x 3 positions, velocities, angular velocities, n x 4 (w, x, y, z)).
  state(frame, pos, vel, quat, angvel) {
    this.sFrame.push([BigInt(frame)]);
    this.sPos.push(pos);
    this.sVel.push(vel);
    this.sQ.push(quat);
    this.sW.push(angvel);
    this.maybeFlush();
  }

  /// Appends the contact rows of step `frame`: [{a, b, n, p, depth, jn, jt, jt3?}], a < b; sorted
  /// here by (a, b), a pair's rows kept in the order given.
  contacts(frame, rows) {
    rows.forEach((r, k) => { r.k = k; });
    rows.sort((x, y) => x.a - y.a || x.b - y.b || x.k - y.k);
    for (const r of rows) {
      this.cPair.push([r.a, r.b]);
      this.cNormal.push(r.n);
      this.cPoint.push(r.p);
      this.cDepth.push([r.depth]);
      this.cJn.push([r.jn]);
      this.cJt.push([r.jt]);
      if (this.cJt3) this.cJt3.push(r.jt3);
    }
    this.contactRows += rows.length;
    this.cOffsets.push([BigInt(this.contactRows)]);
    this.cFrame.push([BigInt(frame)]);
    this.maybeFlush();
  }

  maybeFlush() {
    let bytes = 0;
    for (const c of this.columns) bytes += c.bytes;
    if (bytes >= kBatchBytes) this.flush();
  }

  flush() {
    for (const c of this.columns) c.flush();
    this.f.flush();
  }

  /// Writes what is buffered, the root attributes known at the end, closes and renames onto the trace.
  close(endAttrs) {
    this.flush();
    for (const [k, a] of Object.entries(endAttrs)) setAttr(this.f, k, a);
    this.f.close();
    renameSync(this.partial, this.path);
  }

  /// Closes and removes the partial file (after a failure).
  abandon() {
    try { this.f.close(); } catch { /* already closed */ }
    rmSync(this.partial, { force: true });
  }
}
