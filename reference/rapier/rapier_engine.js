#!/usr/bin/env node
// Rapier 0.21 (@dimforge/rapier3d-compat, WebAssembly) as an octocd process engine:
//   node rapier_engine.js REQUEST.json   runs the request and writes its version 2 trace
//   node rapier_engine.js --check        exits 0 when Node.js and the packages load
// What maps exactly, approximately or not at all, and the traps of Rapier's contact API:
// docs/engines.md, "Rapier".
import RAPIER from "@dimforge/rapier3d-compat";
import { main } from "../js-common/run.js";
import { parseSettings, intIn } from "../js-common/request.js";
import { str, i32, f64 } from "../js-common/trace.js";
import { principalAxes, toWorld, sub, dot } from "../js-common/math.js";

const settingsSpec = {
  // Rapier's numSolverIterations: the substeps of its TGS-soft solver (default 4).
  iterations: { def: 4, parse: intIn(1, 64), allowed: "an integer in [1, 64] (Rapier's numSolverIterations)" },
};

// Rapier's convex hull of one mesh, built once and shared by the colliders of every body of
// that mesh, as Rust's SharedShape (an Arc) is shared. ColliderSet.createCollider asks the
// descriptor's shape for a raw shape per collider (Shape.intoRaw), lends it to the new collider
// (which clones the Arc) and frees the handle after; a ConvexPolyhedron without indices
// computes its hull in intoRaw, so once per body (17-193 s of set-up on Table 5's scenes). This
// shape computes it once and hands out the same raw shape, whose free() is made a no-op.
function sharedHull(R, points, file, mesh) {
  const shape = new R.ConvexPolyhedron(points, null);
  const raw = shape.intoRaw();
  if (!raw) throw new Error(`${file}: meshes[${mesh}]: Rapier cannot build its convex hull`);
  raw.free = () => {};
  shape.intoRaw = () => raw;
  return shape;
}

const engine = {
  script: "rapier_engine.js",
  async load() { await RAPIER.init(); },
  describe() { return `rapier ${RAPIER.version()}`; },
  create(req) { return new RapierWorld(req, parseSettings(req, settingsSpec)); },
};

class RapierWorld {
  constructor(req, settings) {
    const R = RAPIER;
    this.req = req;
    this.n = req.bodies.length;
    const world = new R.World({ x: req.gravity[0], y: req.gravity[1], z: req.gravity[2] });
    world.timestep = req.dt;
    world.numSolverIterations = settings.iterations;
    this.world = world;
    this.bodies = [];
    this.colliders = [];
    this.indexOfCollider = new Map();  // collider handle -> octocd body index
    const hullCache = new Map();
    const shapes = [];
    req.bodies.forEach((b, i) => {
      const q = { w: b.orientation[0], x: b.orientation[1], y: b.orientation[2], z: b.orientation[3] };
      const desc = (b.static ? R.RigidBodyDesc.fixed() : R.RigidBodyDesc.dynamic())
        .setTranslation(...b.position).setRotation(q).setCanSleep(false)
        .setLinearDamping(0).setAngularDamping(0);
      if (!b.static) desc.setLinvel(...b.velocity).setAngvel({ x: b.angular_velocity[0], y: b.angular_velocity[1], z: b.angular_velocity[2] });
      const body = world.createRigidBody(desc);
      let cd;
      if (b.shape === "box") {
        cd = R.ColliderDesc.cuboid(...b.half_extents);
        shapes.push("mesh");
      } else {
        const m = req.meshes[b.mesh];
        if (b.static) {
          cd = R.ColliderDesc.trimesh(Float32Array.from(m.vertexArray), m.triangleArray);
          shapes.push("mesh");
        } else {
          if (!hullCache.has(b.mesh)) hullCache.set(b.mesh, sharedHull(R, Float32Array.from(m.vertexArray), req.file, b.mesh));
          cd = new R.ColliderDesc(hullCache.get(b.mesh));
          shapes.push("convex_hull");
        }
      }
      cd.setFriction(b.friction).setRestitution(b.restitution)
        .setFrictionCombineRule(R.CoefficientCombineRule.Average)
        .setRestitutionCombineRule(R.CoefficientCombineRule.Average);
      if (b.static) {
        cd.setDensity(0);
      } else {
        // The request's mass and inertia about the body origin (its centre of mass), as principal moments.
        const p = principalAxes(b.inertia);
        cd.setMassProperties(b.mass, { x: 0, y: 0, z: 0 }, { x: p.values[0], y: p.values[1], z: p.values[2] },
                             { w: p.frame[0], x: p.frame[1], y: p.frame[2], z: p.frame[3] });
      }
      const c = world.createCollider(cd, body);
      this.bodies.push(body);
      this.colliders.push(c);
      this.indexOfCollider.set(c.handle, i);
    });
    const ip = world.integrationParameters;
    this.prediction = ip.normalizedPredictionDistance * ip.lengthUnit;
    this.substeps = world.numSolverIterations;
    this.name = `rapier ${R.version()}`;
    this.attrs = {
      friction_combine: str("average"), restitution_combine: str("average"),
      contact_margin: f64(this.prediction), deactivation: str("off"), broadphase_exact: i32(0),
      impulse_points: str("one"), friction_directions: i32(2),
      integrator: str("substepped"), substeps: i32(this.substeps), impulses: str("normal-only"),
      speculative: i32(1), manifold_points: str("persistent"), depth_per: str("point"),
      parameters_rapier: str(JSON.stringify({ numSolverIterations: this.substeps,
        numInternalPgsIterations: world.numInternalPgsIterations, predictionDistance: this.prediction,
        lengthUnit: ip.lengthUnit, allowedLinearError: ip.normalizedAllowedLinearError * ip.lengthUnit,
        contactErp: ip.contact_erp, dt: world.timestep })),
    };
    this.bodyData = { collision_shape: { strings: shapes } };
    this.jt3 = false;
    this.matchWorst = 0;  // the largest distance between a solver contact and its tracked point's midpoint (m)
    this.staleDropped = 0;  // solver contacts beyond the prediction distance without impulse, not written
    this.frame = 0;
    this.apartRows = 0;  // rows on pairs Rapier's own contactShape puts beyond the prediction distance
    this.apartWorst = 0;  // their worst distance (m)
    this.apartJn = 0;  // the largest summed impulse on such a pair in one step (N s), and where
    this.apartJnAt = "";
    this.apartLoaded = new Set();  // pairs "(i, j)" the solver loaded while apart
    this.missedPairs = 0;  // pair-steps (every 5th frame) contactShape finds penetrating (> 0.1 mm) without solver contacts
    this.missedWorst = 0;
    this.missedAt = "";
    this.depthGap = 0;  // the largest contactShape penetration beyond the pair's deepest row (m)
    this.depthGapAt = "";
    this.ownAngular = new Map();  // isolated group "(a, b, ...)" -> its largest own angular momentum change beyond 5e-4
    this.witnessTime = 0;
    this.deepestOwn = 0;  // the deepest contactShape penetration of a pair with rows (m), where, and its rows' deepest depth
    this.deepestOwnAt = "";
    this.deepestOwnRows = 0;
    this.duplicateTies = 0;  // solver contacts with coincident tracked points, told apart by a changed impulse
    this.duplicateUnresolved = 0;
    this.duplicateAmbiguous = 0;  // ... where several changed to different impulses (the first taken)
    this.duplicateAmbiguousWorst = 0;  // the largest difference of their impulses (N s), and where
    this.duplicateAmbiguousAt = "";  // ... where none changed nor read 0 (the nearest kept)
    this.lastImpulse = new Map();  // pair -> manifold:point -> the impulse read the previous step
    this.tangentSeen = 0;  // rows whose tangent impulse Rapier reported non-zero (a witness)
  }

  step() {
    this.frame += 1;
    const t0 = process.hrtime.bigint();
    this.preSnap = this.snapshot();
    this.witnessTime = Number(process.hrtime.bigint() - t0) * 1e-9;
    this.world.step();
  }

  // Seconds spent in witness snapshots during the last step (not the engine's step time).
  witnessSeconds() { return this.witnessTime; }

  // Rapier's own mass properties and velocities of every dynamic body (RigidBody.mass,
  // worldCom, linvel, angvel, effectiveAngularInertia: the world tensor at the body's pose).
  snapshot() {
    const out = new Array(this.n);
    for (let i = 0; i < this.n; ++i) {
      if (this.req.bodies[i].static) continue;
      const b = this.bodies[i];
      const c = b.worldCom(), v = b.linvel(), w = b.angvel(), I = b.effectiveAngularInertia();
      out[i] = { m: b.mass(), x: [c.x, c.y, c.z], v: [v.x, v.y, v.z], w: [w.x, w.y, w.z],
                 I: [[I.m11, I.m12, I.m13], [I.m12, I.m22, I.m23], [I.m13, I.m23, I.m33]] };
    }
    return out;
  }

  // Witness from Rapier's own numbers (snapshot before and after the step): the angular momentum
  // about the centre of mass of each isolated group (dynamic bodies whose rows this step name only
  // each other), m (x - c) x v at the pre-step centres plus I w, before and after; its change
  // (kg m^2/s), which contact impulses, equal and opposite at one point, keep but for the free
  // rotation's discretisation.
  ownAngularMomentum(rows) {
    // Isolated groups: the components of this step's rows, all dynamic (no static body among them).
    const parent = new Map();
    const find = (x) => { while (parent.get(x) !== x) { parent.set(x, parent.get(parent.get(x))); x = parent.get(x); } return x; };
    const add = (x) => { if (!parent.has(x)) parent.set(x, x); };
    for (const r of rows) {
      add(r.a); add(r.b);
      const ra = find(r.a), rb = find(r.b);
      if (ra !== rb) parent.set(ra, rb);
    }
    const groups = new Map();
    for (const x of parent.keys()) {
      const root = find(x);
      if (!groups.has(root)) groups.set(root, []);
      groups.get(root).push(x);
    }
    const post = this.snapshot(), pre = this.preSnap;
    const cross = (u, v) => [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
    const mul = (M, v) => [0, 1, 2].map((k) => M[k][0] * v[0] + M[k][1] * v[1] + M[k][2] * v[2]);
    for (const members of groups.values()) {
      if (members.some((i) => !pre[i])) continue;  // a static body among them
      members.sort((x, y) => x - y);
      let M = 0;
      const c0 = [0, 0, 0];
      for (const i of members) {
        M += pre[i].m;
        for (let k = 0; k < 3; ++k) c0[k] += pre[i].m * pre[i].x[k];
      }
      for (let k = 0; k < 3; ++k) c0[k] /= M;
      let dl = [0, 0, 0], exchanged = 0;
      for (const i of members) {
        const li = cross(sub(pre[i].x, c0), sub(post[i].v, pre[i].v)).map((x) => x * pre[i].m);
        const spin = sub(mul(post[i].I, post[i].w), mul(pre[i].I, pre[i].w));
        const d = [li[0] + spin[0], li[1] + spin[1], li[2] + spin[2]];
        dl = [dl[0] + d[0], dl[1] + d[1], dl[2] + d[2]];
        exchanged += Math.hypot(...d);
      }
      const change = Math.hypot(...dl);
      const key = `(${members.join(", ")})`;
      if (change > 5e-4) {
        const was = this.ownAngular.get(key);
        if (!was || change > was.change) this.ownAngular.set(key, { change, exchanged, frame: this.frame });
      }
    }
  }



  readState(pos, vel, quat, angvel) {
    for (let i = 0; i < this.n; ++i) {
      const b = this.bodies[i];
      const t = b.translation(), r = b.rotation(), v = b.linvel(), w = b.angvel();
      pos[3 * i] = t.x; pos[3 * i + 1] = t.y; pos[3 * i + 2] = t.z;
      quat[4 * i] = r.w; quat[4 * i + 1] = r.x; quat[4 * i + 2] = r.y; quat[4 * i + 3] = r.z;
      vel[3 * i] = v.x; vel[3 * i + 1] = v.y; vel[3 * i + 2] = v.z;
      angvel[3 * i] = w.x; angvel[3 * i + 1] = w.y; angvel[3 * i + 2] = w.z;
    }
    this.pos = pos;
    this.quat = quat;
  }

  // The rows of the step just taken: each manifold's SOLVER contacts (the points the solver used
  // this step; a tracked point it skipped keeps the impulse of the last step that solved it),
  // each matched to its tracked point for the impulse; depth and point from the tracked local
  // points at the detection pose (the pre-step state: contactDist stays frozen while Rapier
  // reuses a manifold).
  contacts(prePos, preQuat) {
    const rows = [];
    const nextImpulse = new Map();  // pair -> manifold:point -> the impulse read this step
    const world = this.world, np = world.narrowPhase;
    const pose = (P, Q, i) => [[P[3 * i], P[3 * i + 1], P[3 * i + 2]], [Q[4 * i], Q[4 * i + 1], Q[4 * i + 2], Q[4 * i + 3]]];
    for (let i = 0; i < this.n; ++i) {
      const ci = this.colliders[i];
      np.contactPairsWith(ci.handle, (h2) => {
        const j = this.indexOfCollider.get(h2);
        if (j === undefined || j <= i) return;
        const key = `${i},${j}`;
        const prevImpulse = this.lastImpulse.get(key) || new Map();
        const nowImpulse = new Map();
        let manifoldIndex = 0, written = 0, pairJn = 0, deepest = 0, solverContacts = 0;
        world.contactPair(ci, this.colliders[j], (m, flipped) => {
          for (let k = 0; k < m.numContacts(); ++k) nowImpulse.set(`${manifoldIndex}:${k}`, m.contactImpulse(k));
          const ns = m.numSolverContacts();
          if (ns === 0) { manifoldIndex += 1; return; }
          solverContacts += ns;
          const s1 = flipped ? j : i, s2 = flipped ? i : j;  // the bodies of m's shape 1 and 2
          const [x1, q1] = pose(prePos, preQuat, s1), [x2, q2] = pose(prePos, preQuat, s2);
          const [y1, r1] = pose(this.pos, this.quat, s1), [y2, r2] = pose(this.pos, this.quat, s2);
          // The world normal the solver applies the rows' impulses along, from shape 1 to shape 2
          // (Rapier keeps it, with contactDist, while it reuses the manifold: not localNormal1
          // turned with body 1).
          const wn = m.normal();
          const n1 = [wn.x, wn.y, wn.z];
          const nt = m.numContacts();
          const tracked = [];
          for (let k = 0; k < nt; ++k) {
            const a = m.localContactPoint1(k), b = m.localContactPoint2(k);
            const la = [a.x, a.y, a.z], lb = [b.x, b.y, b.z];
            const cur1 = toWorld(y1, r1, la), cur2 = toWorld(y2, r2, lb);
            tracked.push({ k, la, lb, mid: [(cur1[0] + cur2[0]) / 2, (cur1[1] + cur2[1]) / 2, (cur1[2] + cur2[2]) / 2] });
          }
          const used = new Set();
          const mi = manifoldIndex++;

          for (let s = 0; s < ns; ++s) {
            const sp = m.solverContactPoint(s);
            const spv = [sp.x, sp.y, sp.z];
            let best = -1, bestD = Infinity;
            for (const t of tracked) {
              if (used.has(t.k)) continue;
              const d = Math.hypot(...sub(t.mid, spv));
              if (d < bestD) { bestD = d; best = t.k; }
            }
            // Rapier may track the same point twice (same local points, same contactDist); the
            // solver uses one of them, the other keeps the impulse of the last step that solved
            // it, bit for bit. Among tracked points as near as the best (within 1e-7 m), one whose
            // impulse changed since the previous step's read is one this step solved; a point the
            // previous step did not track (a new point of the manifold) holds no impulse of an
            // earlier step, so a non-zero impulse there is this step's (bunny-stack-50, frame 351,
            // pair (35, 44): of two new coincident points the first read 0 and the second 0.474
            // N s, and taking the first dropped that impulse from body 35's and 44's balance).
            const ties = tracked.filter((t) => !used.has(t.k) && Math.hypot(...sub(t.mid, spv)) <= bestD + 1e-7);
            if (ties.length > 1) {
              this.duplicateTies += 1;
              const fresh = ties.filter((t) => {
                const before = prevImpulse.get(`${mi}:${t.k}`);
                return before === undefined ? m.contactImpulse(t.k) !== 0 : before !== m.contactImpulse(t.k);
              });
              // None changed: a solved point whose impulse stays bit for bit is one that stays 0.
              const zero = ties.filter((t) => m.contactImpulse(t.k) === 0);
              // Two or more changed with different impulses (bunny-stack-50, frame 530, pair (8, 26):
              // 0.036 -> 0 and 0 -> 0.0168 N s): Rapier's JavaScript API names no tracked point of a
              // solver contact, so the writer cannot tell which one this step solved (taking the
              // non-zero one there fails other bodies elsewhere): counted, the largest difference kept.
              const values = new Set(fresh.map((t) => m.contactImpulse(t.k)));
              if (values.size > 1) {
                this.duplicateAmbiguous += 1;
                const spread = Math.max(...values) - Math.min(...values);
                if (spread > this.duplicateAmbiguousWorst) {
                  this.duplicateAmbiguousWorst = spread;
                  this.duplicateAmbiguousAt = `frame ${this.frame} pair (${i}, ${j})`;
                }
              }
              if (fresh.length > 0) best = fresh[0].k;
              else if (zero.length > 0) best = zero[0].k;
              else this.duplicateUnresolved += 1;
            }
            if (best < 0) throw new Error(`pair (${i}, ${j}): solver contact ${s} has no tracked point`);
            used.add(best);
            this.matchWorst = Math.max(this.matchWorst, bestD);
            const t = tracked[best];
            const w1 = toWorld(x1, q1, t.la), w2 = toWorld(x2, q2, t.lb);
            const dist = dot(sub(w2, w1), n1);
            // octocd's normal points from B (the larger index) to A: +n1 when shape 1 is B.
            const sign = s1 === j ? 1 : -1;
            if (m.contactTangentImpulseX(best) !== 0 || m.contactTangentImpulseY(best) !== 0) this.tangentSeen += 1;
            const jn = m.contactImpulse(best);
            // A solver contact of a recycled manifold that lies beyond the prediction distance and
            // carried no impulse is no contact (Rapier keeps them while a separating pair's manifold
            // is reused): not a row, counted.
            if (jn === 0 && dist > this.prediction) { this.staleDropped += 1; continue; }
            written += 1;
            pairJn += jn;
            deepest = Math.max(deepest, -dist);
            rows.push({ a: i, b: j, n: [sign * n1[0], sign * n1[1], sign * n1[2]],
                        p: [(w1[0] + w2[0]) / 2, (w1[1] + w2[1]) / 2, (w1[2] + w2[2]) / 2],
                        depth: Math.max(0, -dist), jn, jt: 0 });
          }
        });
        this.witness(i, j, prePos, preQuat, written, pairJn, deepest, solverContacts);
        if (nowImpulse.size > 0) nextImpulse.set(key, nowImpulse);
      });
    }
    this.lastImpulse = nextImpulse;
    this.ownAngularMomentum(rows);
    return rows;
  }

  // Witnesses from Rapier's own geometry: the distance its exact query (Shape.contactShape,
  // parry) gives between a contact pair's shapes at the detection pose. Counted: rows written on
  // a pair it puts beyond the prediction distance (with the worst distance, the largest impulse
  // the solver applied on such a pair in one step, and the pairs it loaded); pairs it finds
  // penetrating whose manifolds hold no solver contact (every 5th frame: the query on every
  // pair whose bounding boxes overlap costs more than the step); the largest amount by which its
  // penetration exceeds the pair's deepest row. Static triangle meshes are not queried.
  witness(i, j, P, Q, written, pairJn, deepest, solverContacts) {
    if (written === 0 && (solverContacts > 0 || this.frame % 5 !== 0)) return;  // stale rows only; or not a 5th frame
    const bi = this.req.bodies[i], bj = this.req.bodies[j];
    if ((bi.shape === "mesh" && bi.static) || (bj.shape === "mesh" && bj.static)) return;
    const at = (k) => [{ x: P[3 * k], y: P[3 * k + 1], z: P[3 * k + 2] },
                       { w: Q[4 * k], x: Q[4 * k + 1], y: Q[4 * k + 2], z: Q[4 * k + 3] }];
    const [xi, qi] = at(i), [xj, qj] = at(j);
    const c = this.colliders[i].shape.contactShape(xi, qi, this.colliders[j].shape, xj, qj, 1.0);
    const d = c ? c.distance : Infinity;
    const where = `frame ${this.frame} pair (${i}, ${j})`;
    if (written === 0) {
      if (d < -1e-4) {
        this.missedPairs += 1;
        if (-d > this.missedWorst) { this.missedWorst = -d; this.missedAt = where; }
      }
      return;
    }
    if (d > this.prediction) {
      this.apartRows += written;
      this.apartWorst = Math.max(this.apartWorst, Math.min(d, 1.0));
      if (pairJn > this.apartJn) { this.apartJn = pairJn; this.apartJnAt = where; }
      if (pairJn > 0) this.apartLoaded.add(`(${i}, ${j})`);
    }
    if (-d - deepest > this.depthGap) { this.depthGap = -d - deepest; this.depthGapAt = where; }
    if (-d > this.deepestOwn) { this.deepestOwn = -d; this.deepestOwnAt = where; this.deepestOwnRows = deepest; }
  }

  endAttrs() {
    return { rapier_apart_rows: i32(this.apartRows), rapier_apart_worst_m: f64(this.apartWorst),
             rapier_apart_worst_jn: f64(this.apartJn), rapier_apart_worst_jn_at: str(this.apartJnAt),
             rapier_apart_loaded_pairs: str([...this.apartLoaded].sort().join(" ")),
             rapier_missed_pairs: i32(this.missedPairs), rapier_missed_worst_m: f64(this.missedWorst),
             rapier_missed_worst_at: str(this.missedAt),
             rapier_depth_gap_worst_m: f64(this.depthGap), rapier_depth_gap_worst_at: str(this.depthGapAt),
             rapier_deepest_m: f64(this.deepestOwn), rapier_deepest_at: str(this.deepestOwnAt),
             rapier_deepest_rows_m: f64(this.deepestOwnRows),
             rapier_own_angular_momentum_groups: str([...this.ownAngular].sort((x, y) => y[1].change - x[1].change).slice(0, 60)
               .map(([k, v]) => `${k} ${v.change.toPrecision(4)} of ${v.exchanged.toPrecision(4)} frame ${v.frame}`).join("; ")), rapier_tangent_impulse_rows: i32(this.tangentSeen), rapier_stale_rows_dropped: i32(this.staleDropped),
             rapier_solver_match_worst_m: f64(this.matchWorst), rapier_duplicate_points: i32(this.duplicateTies),
             rapier_duplicate_unresolved: i32(this.duplicateUnresolved),
             rapier_duplicate_ambiguous: i32(this.duplicateAmbiguous),
             rapier_duplicate_ambiguous_worst_jn: f64(this.duplicateAmbiguousWorst),
             rapier_duplicate_ambiguous_worst_at: str(this.duplicateAmbiguousAt) };
  }

  free() { this.world.free(); }
}

await main(engine);
