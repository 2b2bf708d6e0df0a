#!/usr/bin/python3
"""`octocd report`'s pages in headless Chromium (issue 69 item 6, issue 80 item 8): a generated
seven-engine `bench small-scenes` result (cuda skipped on a CPU-only build; rapier and jolt
process engines without stage times) and a divergence result with a skipped engine, each
reported; each page loads from the file alone with no console error, every plot is inline
(<svg> in a <figure>), each plot's record of its engines (dc:description, read as
tests/report/test_report_engines.py reads it) names every engine of the sweep in its
report_plots.ENGINE_COLORS colour, and the screenshot shows each drawn engine's colour on many
pixels (jolt's black aside: text is black too).

Usage: test_report_chromium.py OCTOCD_BIN SOURCE_DIR WORK_DIR [SCREENSHOT_DIR]
(SCREENSHOT_DIR: the pages' screenshots, cropped to their plots, are written there as
report-seven-engines.png and report-divergence.png: docs/images).
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


def page(octocd, source, work, name, result, engines, skipped, Image, keep):
    """Reports `result` with octocd, checks the page in Chromium; returns the pixel counts."""
    from report_plots import ENGINE_COLORS
    from test_report_engines import plot_engines
    path, out = os.path.join(work, f"{name}.json"), os.path.join(work, name)
    with open(path, "w") as f:
        json.dump(result, f)
    # The source tree's report script (the one beside this test), whichever tree built octocd.
    env = dict(os.environ, OCTOCD_REPORT_SCRIPT=os.path.join(source, "report", "make_report.py"))
    rep = subprocess.run([octocd, "report", path, "-o", out], capture_output=True, text=True, env=env)
    if rep.returncode != 0:
        fail(f"{name}: octocd report exit {rep.returncode}:\n{rep.stdout[-2000:]}{rep.stderr[-2000:]}")
    index = os.path.join(out, "index.html")
    url = "file://" + os.path.abspath(index)
    text = open(index).read()
    n_fig = text.count("<figure><svg")
    if n_fig < 2:
        fail(f"{name}: {n_fig} inline plots in {index}; expected at least 2")
    for plot in sorted(os.listdir(os.path.join(out, "plots"))):
        record, drawn = plot_engines(os.path.join(out, "plots", plot))
        if sorted(record) != sorted(engines):
            fail(f"{name}: {plot} names engines {sorted(record)}; expected {sorted(engines)}")
        for e, rec in record.items():
            if rec["colour"].lower() != ENGINE_COLORS[e].lower():
                fail(f"{name}: {plot}: {e} in {rec['colour']}, not its {ENGINE_COLORS[e]}")
            if e not in skipped and ENGINE_COLORS[e].lower() not in {c for _, c in drawn.get(e, set())}:
                fail(f"{name}: {plot}: nothing drawn for {e} in its colour ({drawn.get(e)})")

    dom = dump_dom(url, FLAGS)
    if len(re.findall(r"<figure><svg", dom.stdout)) != n_fig:
        fail(f"{name}: the page's DOM holds {len(re.findall(r'<figure><svg', dom.stdout))} of its {n_fig} plots "
             f"(chromium exit {dom.returncode}):\n{dom.stderr[-3000:]}")
    errors = console_errors(dom.stderr)
    if errors:
        fail(f"{name}: console errors:\n" + "\n".join(errors))
    png = os.path.join(work, f"{name}.png")
    screenshot(url, png, FLAGS)
    import numpy as np
    px = np.asarray(Image.open(png).convert("RGB")).astype(int)

    def near(hexcol, tol=6):
        rgb = np.array([int(hexcol[i:i + 2], 16) for i in (1, 3, 5)])
        return int((np.abs(px - rgb).max(axis=2) < tol).sum())
    counts = {e: near(ENGINE_COLORS[e]) for e in engines if e not in skipped and ENGINE_COLORS[e] != "#000000"}
    print(f"{name}: screenshot {px.shape[1]}x{px.shape[0]}; pixels of each engine's colour: {counts}")
    missing = {e: c for e, c in counts.items() if c < 300}
    if missing:
        fail(f"{name}: engines whose colour is not on the screenshot (fewer than 300 pixels): {missing}")
    if keep:
        # The plots of the page (the rows holding an engine's colour, with a margin), at half
        # size in 64 colours: a small PNG for docs/images.
        mask = np.zeros(px.shape[:2], dtype=bool)
        for e in counts:
            rgb = np.array([int(ENGINE_COLORS[e][i:i + 2], 16) for i in (1, 3, 5)])
            mask |= np.abs(px - rgb).max(axis=2) < 6
        rows = np.where(mask.any(axis=1))[0]
        top, bottom = max(int(rows.min()) - 260, 0), min(int(rows.max()) + 160, px.shape[0])
        im = Image.open(png).convert("RGB").crop((0, top, px.shape[1], bottom))
        im = im.resize((im.width * 2 // 3, im.height * 2 // 3))
        im.quantize(colors=64).save(os.path.join(keep, f"report-{name}.png"), optimize=True)
    return counts


def main():
    octocd, source, work = sys.argv[1], sys.argv[2], sys.argv[3]
    keep = sys.argv[4] if len(sys.argv) > 4 else None
    Image = require()
    sys.path.insert(0, os.path.join(source, "tests", "report"))
    sys.path.insert(0, os.path.join(source, "report"))
    os.environ.setdefault("OCTOCD_BIN", octocd)
    from test_report_engines import SEVEN, divergence, seven_engines
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    page(octocd, source, work, "seven-engines", seven_engines(), SEVEN, ("cuda",), Image, keep)
    page(octocd, source, work, "divergence", divergence("dart"), ["cpu", "bullet", "ode", "dart"], ("dart",), Image,
         keep)
    print("PASS")


if __name__ == "__main__":
    main()
