#!/usr/bin/python3
"""`octocd report --history`'s page in headless Chromium (design.md section 21): it loads from
the file alone (no network: its Content-Security-Policy allows data: images only) and every
plot is drawn: the page's own count of decoded images (<body data-drawn="K/N">, set on
load) equals its number of plots (data-plots) and that of <img> elements, with no console
error; a screenshot shows the plots (many pixels away from the white background, in the
verdict grid's exact colours).

Usage: test_history_chromium.py OCTOCD_BIN SOURCE_DIR WORK_DIR [SCREENSHOT.png]
Exit 0 pass, 1 fail, 77 skipped (no chromium, or no PIL to read the screenshot).
"""
import os
import re
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from headless_chromium import BASE_FLAGS, console_errors, dump_dom, fail, require, screenshot  # noqa: E402

FLAGS = [*BASE_FLAGS, "--window-size=1200,3000"]


def main():
    octocd, source, work = sys.argv[1], sys.argv[2], sys.argv[3]
    keep = sys.argv[4] if len(sys.argv) > 4 else None
    Image = require()
    sys.path.insert(0, os.path.join(source, "tests", "report"))
    from history_synth import make_history
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    hist, out = os.path.join(work, "history"), os.path.join(work, "out")
    make_history(hist, nights=80, points=3, seed=2, creep=(30, 10, 0.02), step=(60, 0.85),
                 flip=(50, ("bullet", "rot-stack-10", "penetration")),
                 expected=[("mujoco", "rot-drop-220", "conservation")])
    subprocess.run([octocd, "report", "--history", hist, "-o", out], check=True, capture_output=True)
    page = os.path.join(out, "index.html")
    url = "file://" + os.path.abspath(page)
    n_img = open(page).read().count("<img ")

    dom = dump_dom(url, FLAGS)
    plots = re.search(r'<body[^>]*data-plots="(\d+)"', dom.stdout)
    drawn = re.search(r'<body[^>]*data-drawn="(\d+)/(\d+)"', dom.stdout)
    if plots is None or drawn is None:
        fail(f"the page's DOM has no data-plots or data-drawn (chromium exit {dom.returncode}):\n{dom.stderr[-3000:]}")
    n = int(plots.group(1))
    if n != 4 or n_img != n:
        fail(f"{n} plots, {n_img} <img> elements; expected 4 (3 series and the verdict grid)")
    if drawn.group(1) != drawn.group(2) or int(drawn.group(2)) != n:
        fail(f"{drawn.group(1)} of {drawn.group(2)} images drawn; expected all {n}")
    errors = console_errors(dom.stderr)
    if errors:
        fail("console errors:\n" + "\n".join(errors))

    png = os.path.join(work, "shot.png")
    screenshot(url, png, FLAGS)
    import numpy as np
    px = np.asarray(Image.open(png).convert("RGB")).astype(int)
    h, w = px.shape[:2]

    def near(rgb, tol=15):
        return int((np.abs(px - np.array(rgb)).max(axis=2) < tol).sum())
    inked = float((px.sum(axis=2) < 700).mean())
    # The verdict grid's colours, exact (the grid is not palette-reduced): new and pass
    # filling its cells, and the legend's swatch of fixed.
    vermillion, green, blue = near((0xD5, 0x5E, 0x00)), near((0x00, 0x9E, 0x73)), near((0x00, 0x72, 0xB2))
    print(f"drawn {drawn.group(1)}/{drawn.group(2)} plots; screenshot {w}x{h}: {inked:.1%} inked, {vermillion} "
          f"vermillion (new), {green} green (pass), {blue} blue (fixed) pixels")
    if inked < 0.03:
        fail(f"the screenshot is nearly blank ({inked:.1%} of it away from white)")
    if vermillion < 200 or green < 200 or blue < 40:
        fail(f"the verdict grid's colours are not on the screenshot (new {vermillion}, pass {green}, fixed {blue} "
             "pixels)")
    if keep:
        shutil.copyfile(png, keep)
    print("PASS")


if __name__ == "__main__":
    main()
