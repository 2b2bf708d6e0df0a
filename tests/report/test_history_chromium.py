#!/usr/bin/python3
"""`octocd report --history`'s page in headless Chromium (design.md section 21): it loads from
the file alone (no network: its Content-Security-Policy allows data: images only) and every
plot is drawn: the page's own count of decoded images (<body data-drawn="K/N">, set on
load) equals its number of plots (data-plots) and that of <img> elements, with no console
error; a screenshot shows the plots (many pixels away from the white background, in the
verdict grid's exact colours).

A second page (issue 80 item 3): five runs of five dates and builds appended on one day by
`octocd history-append`, plus a second run on the last date: every file carries its run's
start and commit, the page counts 6 runs from the first start to the last, and its plots
are drawn.

Usage: test_history_chromium.py OCTOCD_BIN SOURCE_DIR WORK_DIR [SCREENSHOT_DIR]
(SCREENSHOT_DIR: history-report.png and history-five-runs.png are written there: docs/images).
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


def check_page(page, n_expected):
    """The page in Chromium: every plot drawn, no console error; returns the DOM's text."""
    url = "file://" + os.path.abspath(page)
    n_img = open(page).read().count("<img ")
    dom = dump_dom(url, FLAGS)
    plots = re.search(r'<body[^>]*data-plots="(\d+)"', dom.stdout)
    drawn = re.search(r'<body[^>]*data-drawn="(\d+)/(\d+)"', dom.stdout)
    if plots is None or drawn is None:
        fail(f"the page's DOM has no data-plots or data-drawn (chromium exit {dom.returncode}):\n{dom.stderr[-3000:]}")
    n = int(plots.group(1))
    if n != n_expected or n_img != n:
        fail(f"{page}: {n} plots, {n_img} <img> elements; expected {n_expected}")
    if drawn.group(1) != drawn.group(2) or int(drawn.group(2)) != n:
        fail(f"{page}: {drawn.group(1)} of {drawn.group(2)} images drawn; expected all {n}")
    errors = console_errors(dom.stderr)
    if errors:
        fail("console errors:\n" + "\n".join(errors))
    return dom.stdout


def small_png(Image, png, path, height=None):
    """The screenshot cut to its inked rows (and at most `height` px), at 2/3 size, 64 colours."""
    import numpy as np
    px = np.asarray(Image.open(png).convert("RGB"))
    rows = np.where((px < 240).any(axis=2).any(axis=1))[0]
    bottom = min(int(rows.max()) + 20, height or px.shape[0])
    im = Image.open(png).convert("RGB").crop((0, 0, px.shape[1], bottom))
    im.resize((im.width * 2 // 3, im.height * 2 // 3)).quantize(colors=64).save(path, optimize=True)


def five_runs(octocd, work, Image, keep):
    """Five results of five dates and builds, and a second run of the last date, appended on one
    day: the page is dated by the runs."""
    import json
    from history_synth import bench_result
    hist, out = os.path.join(work, "five"), os.path.join(work, "five-out")
    runs = [(f"2026-11-{20 + k}T02:00:00Z", f"c0ffee{k}", 1.0 - 0.02 * k) for k in range(5)]
    runs.append(("2026-11-24T14:30:00Z", "c0ffee4", 0.9))
    for k, (started, commit, level) in enumerate(runs):
        path = os.path.join(work, f"r{k}.json")
        with open(path, "w") as f:
            json.dump(bench_result(started, commit, points=2, level=level), f)
        subprocess.run([octocd, "history-append", hist, "--bench", path], check=True, capture_output=True)
    for name, (started, commit, _) in zip(sorted(os.listdir(hist)), runs):
        with open(os.path.join(hist, name)) as f:
            j = json.load(f)
        if (j["date"], j["build"]["commit"]) != (started, commit):
            fail(f"{name}: dated {j['date']} {j['build']['commit']}; the run started {started} at {commit}")
    subprocess.run([octocd, "report", "--history", hist, "-o", out], check=True, capture_output=True)
    page = os.path.join(out, "index.html")
    dom = check_page(page, 2)
    if "6 run(s), 2026-11-20T02:00:00Z to 2026-11-24T14:30:00Z" not in dom:
        fail("the five-run page does not count its runs from the first start to the last")
    png = os.path.join(work, "five.png")
    screenshot("file://" + os.path.abspath(page), png, FLAGS)
    if keep:
        small_png(Image, png, os.path.join(keep, "history-five-runs.png"))
    print("five runs appended on one day: 6 runs dated by their starts, 2 plots drawn")


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
    check_page(page, 4)  # 3 series and the verdict grid

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
    print(f"screenshot {w}x{h}: {inked:.1%} inked, {vermillion} vermillion (new), {green} green (pass), {blue} blue "
          "(fixed) pixels")
    if inked < 0.03:
        fail(f"the screenshot is nearly blank ({inked:.1%} of it away from white)")
    if vermillion < 200 or green < 200 or blue < 40:
        fail(f"the verdict grid's colours are not on the screenshot (new {vermillion}, pass {green}, fixed {blue} "
             "pixels)")
    if keep:
        small_png(Image, png, os.path.join(keep, "history-report.png"))
    five_runs(octocd, work, Image, keep)
    print("PASS")


if __name__ == "__main__":
    main()
