// The main loop every process engine shares: `ENGINE.js REQUEST.json` reads the request, builds
// the engine's world, writes state 0, then per frame times the step call alone, reads the state
// and the contact rows, and appends them to the trace; `ENGINE.js --check` loads the runtime
// and the packages and exits 0. Exit 1 with one line on stderr on any failure.
import { readRequest, RequestError } from "./request.js";
import { TraceWriter, f64 } from "./trace.js";

/// Runs a process engine. `engine.load()` loads its packages (async); `engine.create(req)`
/// returns a world {name (with version), attrs (declarations), bodyData, jt3, step(),
/// readState(pos, vel, quat, angvel), contacts(prePos, preQuat) -> rows, free()}.
export async function main(engine, argv = process.argv.slice(2)) {
  if (argv.length !== 1 || argv[0] === "--help" || argv[0] === "-h") {
    process.stderr.write(`usage: ${engine.script} REQUEST.json | --check\n` +
                         "Reads an octocd run request and writes its version 2 trace (docs/engines.md).\n");
    process.exit(argv.length === 1 ? 0 : 2);
  }
  let writer = null;
  try {
    await engine.load();
    if (argv[0] === "--check") {
      await TraceWriter.ready();
      process.stdout.write(`${engine.describe()}: runtime node ${process.version}, packages loaded\n`);
      return;
    }
    const req = readRequest(argv[0]);
    const world = engine.create(req);
    writer = await TraceWriter.open(req, world.name, world.attrs, { bodyData: world.bodyData, jt3: world.jt3 });
    const n = req.bodies.length;
    let pos = new Float64Array(3 * n), vel = new Float64Array(3 * n);
    let quat = new Float64Array(4 * n), angvel = new Float64Array(3 * n);
    let prePos = new Float64Array(3 * n), preQuat = new Float64Array(4 * n);
    world.readState(pos, vel, quat, angvel);
    writer.state(0, pos, vel, quat, angvel);
    // Progress for octocd (docs/bring-your-engine.md, "Progress"): `octocd-progress N` on
    // stdout once set up, then at most every 0.5 s and after the last frame.
    const progress = (frame) => process.stdout.write(`octocd-progress ${frame}\n`);
    progress(0);
    let saidAt = process.hrtime.bigint();
    let wall = 0;
    for (let frame = 1; frame <= req.frames; ++frame) {
      [prePos, pos] = [pos, prePos];
      [preQuat, quat] = [quat, preQuat];
      const t0 = process.hrtime.bigint();
      world.step();
      // The engine's witness queries inside the step (world.witnessSeconds) are not its timing.
      wall += Number(process.hrtime.bigint() - t0) * 1e-9 - (world.witnessSeconds ? world.witnessSeconds() : 0);
      world.readState(pos, vel, quat, angvel);
      for (let k = 0; k < pos.length; ++k) {
        if (!Number.isFinite(pos[k]) || !Number.isFinite(vel[k])) {
          throw new Error(`frame ${frame}: body ${Math.floor(k / 3)} has a non-finite position or velocity`);
        }
      }
      writer.contacts(frame, world.contacts(prePos, preQuat));
      writer.state(frame, pos, vel, quat, angvel);
      const now = process.hrtime.bigint();
      if (frame === req.frames || now - saidAt >= 500000000n) {
        progress(frame);
        saidAt = now;
      }
    }
    writer.close({ wall_step_seconds: f64(wall), ...(world.endAttrs ? world.endAttrs() : {}) });
    writer = null;
    world.free();
  } catch (e) {
    if (writer) writer.abandon();
    const msg = e instanceof RequestError ? e.message : `${engine.script}: ${e && e.stack ? e.stack : e}`;
    process.stderr.write(`${msg}\n`);
    process.exit(1);
  }
}
