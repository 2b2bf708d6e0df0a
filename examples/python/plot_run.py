#!/usr/bin/python3
"""Plot a run of an octocd engine from the arrays it returns (no trace, no notebook).

Steps SCENE with octocd's Python module and draws, per frame: the height (y) of every
dynamic body, the kinetic energy and the contacts resolved, and the per-stage wall time.
matplotlib runs headless (Agg) and writes a PNG.

    PYTHONPATH=build/python /usr/bin/python3 examples/python/plot_run.py \
        datasets/scenes/box-stack.json --frames 500 --out box-stack.png
"""
import argparse

import matplotlib

matplotlib.use("Agg")  # headless: no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import octocd  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", help="scene file (JSON, docs/scenes.md)")
    ap.add_argument("--frames", type=int, default=500, help="steps to run (default 500)")
    ap.add_argument("--engine", default="cpu", help="cpu, cuda or bullet (default cpu)")
    ap.add_argument("--out", default="run.png", help="PNG to write (default run.png)")
    args = ap.parse_args()

    eng = octocd.Engine(args.scene, engine=args.engine, record=False)
    dynamic = eng.inverse_masses > 0
    heights = [eng.positions[dynamic, 1]]
    energy, contacts, stage_ms = [], [], {}
    for _ in range(args.frames):
        m = eng.step()
        heights.append(eng.positions[dynamic, 1])  # (dynamic bodies,) float32, m
        energy.append(m["kinetic_energy"])
        contacts.append(m["contacts"])
        for stage, ms in m["stage_ms"].items():
            stage_ms.setdefault(stage, []).append(np.nan if ms is None else ms)
    heights = np.array(heights)
    t = np.arange(args.frames + 1) * eng.scene.dt
    t1 = t[1:]

    fig, ax = plt.subplots(3, 1, figsize=(8, 9), sharex=True)
    ax[0].plot(t, heights, lw=0.8)
    ax[0].set_ylabel("body height y (m)")
    ax[0].set_title(f"{eng.scene.name}: engine {eng.name}, broadphase {eng.broadphase}, "
                    f"{int(dynamic.sum())} dynamic bodies")
    ax[1].plot(t1, energy, color="C0")
    ax[1].set_ylabel("kinetic energy (J)")
    twin = ax[1].twinx()
    twin.plot(t1, contacts, color="C3", lw=0.8)
    twin.set_ylabel("contacts", color="C3")
    ax[2].stackplot(t1, *stage_ms.values(), labels=list(stage_ms))
    ax[2].set_ylabel("wall time per step (ms)")
    ax[2].set_xlabel("simulated time (s)")
    ax[2].legend(loc="upper left", fontsize="small", ncol=3)
    fig.tight_layout()
    fig.savefig(args.out, dpi=100)
    print(f"{args.out}: {args.frames} frames of {eng.scene.name}")


if __name__ == "__main__":
    main()
