#!/usr/bin/python3
"""`octocd report`'s page in headless Chromium with six engines (issue 69 item 6): a generated
`bench small-scenes --engines cpu,cuda,bullet,mujoco,ode,dart` result, reported; the page
loads from the file alone with no console error, every plot is inline (<svg> in a <figure>),
and the screenshot shows each engine's colour of report_plots.ENGINE_COLORS (six colours,
each on many pixels), so the bars of no two engines are drawn alike.

Usage: test_report_chromium.py OCTOCD_BIN SOURCE_DIR WORK_DIR [SCREENSHOT.png]
Exit 0 pass, 1 fail, 77 skipped (no chromium, or no PIL to read the screenshot).
"""
import json
import os
import re
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from headless_chromium import BASE_FLAGS, console_errors, dump_dom, fail, require, screenshot  # noqa: E402

FLAGS = [*BASE_FLAGS, "--window-size=1200,9000"]


def main():
    octocd, source, work = sys.argv[1], sys.argv[2], sys.argv[3]
    keep = sys.argv[4] if len(sys.argv) > 4 else None
    Image = require()
    sys.path.insert(0, os.path.join(source, "tests", "report"))
    sys.path.insert(0, os.path.join(source, "report"))
    from test_report_readable import SIX, small_scenes
    from report_plots import ENGINE_COLORS
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    result, out = os.path.join(work, "small-scenes.json"), os.path.join(work, "out")
    with open(result, "w") as f:
        json.dump(small_scenes(), f)
    # The source tree's report script (the one beside this test), whichever tree built octocd.
    env = dict(os.environ, OCTOCD_REPORT_SCRIPT=os.path.join(source, "report", "make_report.py"))
    rep = subprocess.run([octocd, "report", result, "-o", out], capture_output=True, text=True, env=env)
    if rep.returncode != 0:
        fail(f"octocd report exit {rep.returncode}:\n{rep.stdout[-2000:]}{rep.stderr[-2000:]}")
    page = os.path.join(out, "index.html")
    url = "file://" + os.path.abspath(page)
    text = open(page).read()
    n_fig = text.count("<figure><svg")
    if n_fig < 2:
        fail(f"{n_fig} inline plots in {page}; expected the steps/s bars and the stage shares")

    dom = dump_dom(url, FLAGS)
    if len(re.findall(r"<figure><svg", dom.stdout)) != n_fig:
        fail(f"the page's DOM holds {len(re.findall(r'<figure><svg', dom.stdout))} of its {n_fig} plots "
             f"(chromium exit {dom.returncode}):\n{dom.stderr[-3000:]}")
    errors = console_errors(dom.stderr)
    if errors:
        fail("console errors:\n" + "\n".join(errors))

    png = os.path.join(work, "shot.png")
    screenshot(url, png, FLAGS)
    import numpy as np
    px = np.asarray(Image.open(png).convert("RGB")).astype(int)

    def near(hexcol, tol=6):
        rgb = np.array([int(hexcol[i:i + 2], 16) for i in (1, 3, 5)])
        return int((np.abs(px - rgb).max(axis=2) < tol).sum())
    counts = {e: near(ENGINE_COLORS[e]) for e in SIX}
    print(f"screenshot {px.shape[1]}x{px.shape[0]}; pixels of each engine's colour: {counts}")
    missing = {e: c for e, c in counts.items() if c < 300}
    if missing:
        fail(f"engines whose colour is not on the screenshot (fewer than 300 pixels): {missing}")
    if keep:
        shutil.copyfile(png, keep)
    print("PASS")


if __name__ == "__main__":
    main()
