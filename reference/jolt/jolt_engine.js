#!/usr/bin/env node
// Jolt Physics 1.1 (jolt-physics, WebAssembly) as an octocd process engine:
//   node jolt_engine.js REQUEST.json   runs the request and writes its version 2 trace
//   node jolt_engine.js --check        exits 0 when Node.js and the packages load
// What maps exactly, approximately or not at all, and the traps of Jolt's contact API:
// docs/engines.md, "Jolt".
import initJolt from "jolt-physics";
import { createRequire } from "node:module";
import { main } from "../js-common/run.js";
import { parseSettings, intIn } from "../js-common/request.js";
import { str, i32, f64 } from "../js-common/trace.js";

const joltVersion = createRequire(import.meta.url)("jolt-physics/package.json").version;
let Jolt = null;

const settingsSpec = {
  // PhysicsSettings::mNumVelocitySteps (Jolt's default 10).
  iterations: { def: 10, parse: intIn(1, 255), allowed: "an integer in [1, 255] (Jolt's mNumVelocitySteps)" },
  // PhysicsSettings::mNumPositionSteps (Jolt's default 2).
  position_iterations: { def: 2, parse: intIn(0, 255), allowed: "an integer in [0, 255] (Jolt's mNumPositionSteps)" },
  // Sub-steps of dt / n per frame, each a full Jolt step (detect, solve, integrate).
  collision_steps: { def: 1, parse: intIn(1, 64), allowed: "an integer in [1, 64] (Jolt steps of dt / n a frame)" },
};

const engine = {
  script: "jolt_engine.js",
  async load() { if (!Jolt) Jolt = await initJolt(); },
  describe() { return `jolt ${joltVersion}`; },
  create(req) { return new JoltWorld(req, parseSettings(req, settingsSpec)); },
};

const kNonMoving = 0, kMoving = 1;

function vec3(v) { return new Jolt.Vec3(v[0], v[1], v[2]); }

class JoltWorld {
  constructor(req, settings) {
    const J = Jolt;
    this.req = req;
    this.n = req.bodies.length;
    this.collisionSteps = settings.collision_steps;
    const objectFilter = new J.ObjectLayerPairFilterTable(2);
    objectFilter.EnableCollision(kNonMoving, kMoving);
    objectFilter.EnableCollision(kMoving, kMoving);
    const bpInterface = new J.BroadPhaseLayerInterfaceTable(2, 2);
    bpInterface.MapObjectToBroadPhaseLayer(kNonMoving, new J.BroadPhaseLayer(0));
    bpInterface.MapObjectToBroadPhaseLayer(kMoving, new J.BroadPhaseLayer(1));
    const js = new J.JoltSettings();
    js.mMaxBodies = this.n + 16;
    // Bounded by Jolt's temporary allocator (10 MB in the WebAssembly build: about 470 bytes a
    // contact constraint per step).
    js.mMaxBodyPairs = Math.max(1024, 32 * this.n);
    js.mMaxContactConstraints = Math.min(20000, Math.max(1024, 10 * this.n));
    js.mMaxWorkerThreads = 0;
    js.mObjectLayerPairFilter = objectFilter;
    js.mBroadPhaseLayerInterface = bpInterface;
    js.mObjectVsBroadPhaseLayerFilter = new J.ObjectVsBroadPhaseLayerFilterTable(bpInterface, 2, objectFilter, 2);
    this.jolt = new J.JoltInterface(js);
    J.destroy(js);
    const system = this.jolt.GetPhysicsSystem();
    this.system = system;
    const ps = system.GetPhysicsSettings();
    ps.mAllowSleeping = false;
    ps.mNumVelocitySteps = settings.iterations;
    ps.mNumPositionSteps = settings.position_iterations;
    system.SetPhysicsSettings(ps);
    this.margin = ps.mSpeculativeContactDistance;
    this.physicsSettings = { mNumVelocitySteps: ps.mNumVelocitySteps, mNumPositionSteps: ps.mNumPositionSteps,
                             mSpeculativeContactDistance: ps.mSpeculativeContactDistance, mBaumgarte: ps.mBaumgarte,
                             mPenetrationSlop: ps.mPenetrationSlop, collisionSteps: this.collisionSteps,
                             mBodyPairCacheCosMaxDeltaRotationDiv2: ps.mBodyPairCacheCosMaxDeltaRotationDiv2,
                             mBodyPairCacheMaxDeltaPositionSq: ps.mBodyPairCacheMaxDeltaPositionSq };
    // Jolt reuses a body pair's cached manifolds (normals included, turned with the bodies)
    // while the pair's relative rotation stays within this angle of the step they were
    // found on: ContactConstraintManager::GetContactsFromCache (2 degrees by default).
    this.normalReuseDeg = 2 * Math.acos(Math.min(1, ps.mBodyPairCacheCosMaxDeltaRotationDiv2)) * 180 / Math.PI;
    system.SetGravity(vec3(req.gravity));
    const bi = system.GetBodyInterface();
    this.bi = bi;
    this.ids = [];
    this.bodies = [];
    this.localBounds = [];  // per body: Jolt's own local bounds of its shape (Shape::GetLocalBounds)
    this.indexOfBody = new Map();  // Jolt body ID -> octocd body index
    const shapeCache = new Map();
    const collisionShapes = [];
    req.bodies.forEach((b, i) => {
      const key = b.shape === "box" ? `box:${b.half_extents.join(",")}:${b.static}` : `mesh:${b.mesh}:${b.static}`;
      if (!shapeCache.has(key)) shapeCache.set(key, this.makeShape(b));
      const shape = shapeCache.get(key);
      collisionShapes.push(b.shape === "mesh" && !b.static ? "convex_hull" : "mesh");
      const q = b.orientation;
      const cs = new J.BodyCreationSettings(shape, new J.RVec3(...b.position), new J.Quat(q[1], q[2], q[3], q[0]),
                                            b.static ? J.EMotionType_Static : J.EMotionType_Dynamic,
                                            b.static ? kNonMoving : kMoving);
      cs.mFriction = b.friction;
      cs.mRestitution = b.restitution;
      cs.mLinearDamping = 0;
      cs.mAngularDamping = 0;
      cs.mAllowSleeping = false;
      cs.mMotionQuality = J.EMotionQuality_Discrete;
      cs.mMaxLinearVelocity = 1e6;
      cs.mMaxAngularVelocity = 1e6;
      cs.mUserData = i;
      if (!b.static) {
        cs.mLinearVelocity = vec3(b.velocity);
        cs.mAngularVelocity = vec3(b.angular_velocity);
        cs.mOverrideMassProperties = J.EOverrideMassProperties_MassAndInertiaProvided;
        const mp = cs.mMassPropertiesOverride;
        mp.mMass = b.mass;
        const I = b.inertia;
        const m = new J.Mat44();
        for (let c = 0; c < 3; ++c) m.SetColumn4(c, new J.Vec4(new J.Vec3(I[0][c], I[1][c], I[2][c]), 0));
        m.SetColumn4(3, new J.Vec4(new J.Vec3(0, 0, 0), 1));
        mp.mInertia = m;
        cs.mMassPropertiesOverride = mp;
      }
      const body = bi.CreateBody(cs);
      J.destroy(cs);
      bi.AddBody(body.GetID(), J.EActivation_Activate);
      this.bodies.push(body);
      const lb = shape.GetLocalBounds();  // in the shape's centre-of-mass frame
      this.localBounds.push([[lb.mMin.GetX(), lb.mMin.GetY(), lb.mMin.GetZ()], [lb.mMax.GetX(), lb.mMax.GetY(), lb.mMax.GetZ()]]);
      this.indexOfBody.set(body.GetID().GetIndexAndSequenceNumber(), i);
    });
    this.pending = [];
    this.installListener();
    this.name = `jolt ${joltVersion}`;
    const n = this.collisionSteps;
    this.attrs = {
      // Jolt combines friction as the geometric mean and restitution as the maximum (its defaults).
      // Its friction (Jolt 5.6, jolt-physics 1.1) is one impulse per manifold at the mean of its
      // points within mu times the manifold's summed normal impulse, and a torsion about the normal.
      friction_combine: str("geometric"), restitution_combine: str("max"), friction_per: str("manifold"),
      contact_margin: f64(this.margin), deactivation: str("off"), broadphase_exact: i32(0),
      impulse_points: str("witness-pair"), gyroscopic: str("false"),
      impulses: str("none"), speculative: i32(1), depth_per: str("point"), normal_reuse_deg: f64(this.normalReuseDeg),
      ...(n === 1 ? { integrator: str("semi-implicit") } : { integrator: str("substepped"), substeps: i32(n) }),
      parameters_jolt: str(JSON.stringify(this.physicsSettings)),
    };
    this.bodyData = { collision_shape: { strings: collisionShapes },
                      convex_radius: { f64: new Float64Array(this.n) } };
    this.jt3 = false;
    this.frame = 0;
    // Witnesses from Jolt's own API (root attributes jolt_*, docs/engines.md, "Jolt"): the
    // largest distance across the normal between a manifold point's two witness points
    // (GetWorldSpaceContactPointOn1/2), and the largest angle between a manifold's normal and
    // the penetration axis of Jolt's own fresh query (TransformedShape::CollideShape, body 1's
    // shape against body 2 at the same pose: CollisionDispatch, no body-pair cache) on every
    // 5th frame, each with where it was.
    this.apartAcross = 0;
    this.offBounds = 0;  // the largest distance of a manifold's witness point outside its own body's local bounds (m)
    this.offBoundsAt = "";
    this.offBoundsPairs = new Map();  // pair "(a, b)" -> its worst such point beyond 1 cm and its frame
    this.apartAcrossAt = "";
    this.freshAngle = 0;
    this.freshAngleAt = "";
    this.freshDepth = 0;  // Jolt's fresh penetration depth at the worst angle (m)
    this.freshManifoldDepth = 0;  // the manifold's mPenetrationDepth there (m)
    this.freshPairs = 0;
    this.witnessTime = 0;  // s, this step's witness queries
    this.freshSettings = new J.CollideShapeSettings();
    this.freshSettings.mMaxSeparationDistance = this.margin;
    this.unitScale = new J.Vec3(1, 1, 1);
    this.shapeFilter = new J.ShapeFilter();
  }

  // Jolt's own fresh narrow phase for the manifold m of bodies b1, b2 (a, b in octocd's order):
  // the angle between m's normal n12 and the penetration axis of the deepest hit.
  freshWitness(b1, b2, m, n12, a, b) {
    const J = Jolt;
    const t0 = process.hrtime.bigint();
    const col = new J.CollideShapeClosestHitCollisionCollector();
    b2.GetTransformedShape().CollideShape(b1.GetShape(), this.unitScale, b1.GetCenterOfMassTransform(),
                                          this.freshSettings, m.mBaseOffset, col, this.shapeFilter);
    if (col.HadHit()) {
      const h = col.mHit;
      // mPenetrationAxis: the direction to move shape 2 out of collision, as the manifold's normal.
      const ax = h.mPenetrationAxis, axis = [ax.GetX(), ax.GetY(), ax.GetZ()];
      const len = Math.hypot(...axis);
      const depth = h.mPenetrationDepth;
      if (len > 0 && depth > 1e-5) {
        this.freshPairs += 1;
        const c = (axis[0] * n12[0] + axis[1] * n12[1] + axis[2] * n12[2]) / len;
        const deg = Math.acos(Math.max(-1, Math.min(1, c))) * 180 / Math.PI;
        if (deg > this.freshAngle) {
          this.freshAngle = deg;
          this.freshAngleAt = `frame ${this.frame} pair (${a}, ${b})`;
          this.freshDepth = depth;
          this.freshManifoldDepth = m.mPenetrationDepth;
        }
      }
    }
    J.destroy(col);
    this.witnessTime += Number(process.hrtime.bigint() - t0) * 1e-9;
  }

  // How far (m) the world point w lies outside Jolt's own local bounds of body i's shape (at the
  // body's centre-of-mass transform; 0 inside).
  outsideBounds(body, i, w) {
    const c = body.GetCenterOfMassPosition(), q = body.GetRotation();
    const d = [w[0] - c.GetX(), w[1] - c.GetY(), w[2] - c.GetZ()];
    const qw = q.GetW(), qv = [q.GetX(), q.GetY(), q.GetZ()];
    // The inverse rotation of d: R^T d with the conjugate quaternion.
    const cross = (u, v) => [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
    const neg = [-qv[0], -qv[1], -qv[2]];
    const t = cross(neg, d).map((x) => 2 * x);
    const u = cross(neg, t);
    const l = [d[0] + qw * t[0] + u[0], d[1] + qw * t[1] + u[1], d[2] + qw * t[2] + u[2]];
    const [lo, hi] = this.localBounds[i];
    let sq = 0;
    for (let k = 0; k < 3; ++k) {
      const e = Math.max(lo[k] - l[k], 0, l[k] - hi[k]);
      sq += e * e;
    }
    return Math.sqrt(sq);
  }

  // Seconds spent in witness queries during the last step (not the engine's step time).
  witnessSeconds() {
    const t = this.witnessTime;
    this.witnessTime = 0;
    return t;
  }

  // A box or hull with convex radius 0 (Jolt rounds convex shapes by 5 cm by default) whose centre
  // of mass is the body origin (Jolt puts a shape's own volume centroid there otherwise); a static
  // mesh as a triangle mesh.
  makeShape(b) {
    const J = Jolt;
    let settings;
    if (b.shape === "box") {
      settings = new J.BoxShapeSettings(vec3(b.half_extents), 0);
    } else {
      const m = this.req.meshes[b.mesh];
      const v = m.vertexArray, t = m.triangleArray;
      if (b.static) {
        const tl = new J.TriangleList();
        tl.resize(t.length / 3);
        for (let k = 0; k < t.length / 3; ++k) {
          const tri = tl.at(k);
          for (let c = 0; c < 3; ++c) {
            const p = tri.get_mV(c), o = 3 * t[3 * k + c];
            p.x = v[o]; p.y = v[o + 1]; p.z = v[o + 2];
          }
        }
        settings = new J.MeshShapeSettings(tl);
      } else {
        settings = new J.ConvexHullShapeSettings();
        for (let k = 0; k < v.length / 3; ++k) settings.mPoints.push_back(new J.Vec3(v[3 * k], v[3 * k + 1], v[3 * k + 2]));
        settings.mMaxConvexRadius = 0;
      }
    }
    let result = settings.Create();
    if (result.HasError()) throw new Error(`${this.req.file}: Jolt cannot build the shape: ${result.GetError().c_str()}`);
    let shape = result.Get();
    if (!b.static) {
      const com = shape.GetCenterOfMass();
      const c = [com.GetX(), com.GetY(), com.GetZ()];
      if (Math.hypot(...c) > 0) {
        const off = new J.OffsetCenterOfMassShapeSettings(new J.Vec3(-c[0], -c[1], -c[2]), settings);
        result = off.Create();
        if (result.HasError()) throw new Error(`${this.req.file}: Jolt cannot centre the shape: ${result.GetError().c_str()}`);
        shape = result.Get();
      }
    }
    shape.AddRef();
    return shape;
  }

  // Every manifold Jolt's narrow phase reports (added or persisted) during the step, at the
  // detection pose; Jolt's JavaScript API gives no impulses.
  installListener() {
    const J = Jolt;
    const listener = new J.ContactListenerJS();
    listener.OnContactValidate = () => J.ValidateResult_AcceptAllContactsForThisBodyPair;
    const record = (b1p, b2p, mp) => {
      if (!this.recording) return;
      const b1 = J.wrapPointer(b1p, J.Body), b2 = J.wrapPointer(b2p, J.Body);
      const m = J.wrapPointer(mp, J.ContactManifold);
      const i1 = this.indexOfBody.get(b1.GetID().GetIndexAndSequenceNumber());
      const i2 = this.indexOfBody.get(b2.GetID().GetIndexAndSequenceNumber());
      const nw = m.mWorldSpaceNormal;  // from body 1 towards body 2
      const n12 = [nw.GetX(), nw.GetY(), nw.GetZ()];
      const [a, b] = i1 < i2 ? [i1, i2] : [i2, i1];
      const s = i1 === a ? -1 : 1;  // octocd's normal: from B to A
      const np = m.mRelativeContactPointsOn1.size();
      for (let k = 0; k < np; ++k) {
        const p1 = m.GetWorldSpaceContactPointOn1(k), p2 = m.GetWorldSpaceContactPointOn2(k);
        const w1 = [p1.GetX(), p1.GetY(), p1.GetZ()], w2 = [p2.GetX(), p2.GetY(), p2.GetZ()];
        // The point's penetration: p1 lies beyond p2 along n (1 -> 2) when the shapes overlap.
        const pen = (w1[0] - w2[0]) * n12[0] + (w1[1] - w2[1]) * n12[1] + (w1[2] - w2[2]) * n12[2];
        const across = Math.hypot(w1[0] - w2[0] - pen * n12[0], w1[1] - w2[1] - pen * n12[1], w1[2] - w2[2] - pen * n12[2]);
        if (across > this.apartAcross) { this.apartAcross = across; this.apartAcrossAt = `frame ${this.frame} pair (${a}, ${b})`; }
        const out = Math.max(this.outsideBounds(b1, i1, w1), this.outsideBounds(b2, i2, w2));
        if (out > this.offBounds) { this.offBounds = out; this.offBoundsAt = `frame ${this.frame} pair (${a}, ${b})`; }
        if (out > 0.01) {
          const key = `(${a}, ${b})`, was = this.offBoundsPairs.get(key);
          if (!was || out > was.out) this.offBoundsPairs.set(key, { out, frame: this.frame });
        }
        this.pending.push({ a, b, n: [s * n12[0], s * n12[1], s * n12[2]],
                            p: [(w1[0] + w2[0]) / 2, (w1[1] + w2[1]) / 2, (w1[2] + w2[2]) / 2],
                            depth: Math.max(0, pen), jn: 0, jt: 0 });
      }
      const static1 = this.req.bodies[i1].static && this.req.bodies[i1].shape === "mesh";
      const static2 = this.req.bodies[i2].static && this.req.bodies[i2].shape === "mesh";
      if (this.frame % 5 === 0 && !static1 && !static2) this.freshWitness(b1, b2, m, n12, a, b);
    };
    listener.OnContactAdded = (b1, b2, m) => record(b1, b2, m);
    listener.OnContactPersisted = (b1, b2, m) => record(b1, b2, m);
    listener.OnContactRemoved = () => {};
    this.system.SetContactListener(listener);
    this.listener = listener;
  }

  // n Jolt steps of dt / n; the rows are those of the first, detected at the pre-step pose.
  step() {
    const n = this.collisionSteps;
    this.recording = true;
    this.frame += 1;
    for (let k = 0; k < n; ++k) {
      this.jolt.Step(this.req.dt / n, 1);
      this.recording = false;
    }
  }

  readState(pos, vel, quat, angvel) {
    for (let i = 0; i < this.n; ++i) {
      const b = this.bodies[i];
      const t = b.GetPosition(), r = b.GetRotation(), v = b.GetLinearVelocity(), w = b.GetAngularVelocity();
      pos[3 * i] = t.GetX(); pos[3 * i + 1] = t.GetY(); pos[3 * i + 2] = t.GetZ();
      quat[4 * i] = r.GetW(); quat[4 * i + 1] = r.GetX(); quat[4 * i + 2] = r.GetY(); quat[4 * i + 3] = r.GetZ();
      vel[3 * i] = v.GetX(); vel[3 * i + 1] = v.GetY(); vel[3 * i + 2] = v.GetZ();
      angvel[3 * i] = w.GetX(); angvel[3 * i + 1] = w.GetY(); angvel[3 * i + 2] = w.GetZ();
    }
  }

  contacts() {
    const rows = this.pending;
    this.pending = [];
    return rows;
  }

  endAttrs() {
    return { jolt_points_apart_across_worst_m: f64(this.apartAcross), jolt_points_apart_across_worst_at: str(this.apartAcrossAt),
             jolt_fresh_normal_angle_worst_deg: f64(this.freshAngle), jolt_fresh_normal_angle_worst_at: str(this.freshAngleAt),
             jolt_fresh_depth_at_worst_m: f64(this.freshDepth), jolt_manifold_depth_at_worst_m: f64(this.freshManifoldDepth),
             jolt_fresh_queries: i32(this.freshPairs),
             jolt_point_outside_own_bounds_worst_m: f64(this.offBounds), jolt_point_outside_own_bounds_worst_at: str(this.offBoundsAt),
             jolt_point_outside_own_bounds_pairs: str([...this.offBoundsPairs].sort((x, y) => y[1].out - x[1].out)
               .map(([k, v]) => `${k} ${v.out.toFixed(4)} m frame ${v.frame}`).join("; ")) };
  }

  free() { Jolt.destroy(this.jolt); }
}

await main(engine);
