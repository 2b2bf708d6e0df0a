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

CHROMIUM = "/usr/bin/chromium"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--enable-logging=stderr", "--window-size=1200,3000",
         "--hide-scrollbars"]


def skip(reason):
    print(f"SKIPPED: {reason}")
    sys.exit(77)


def fail(reason):
    print(f"FAIL: {reason}")
    sys.exit(1)


def main():
    octocd, source, work = sys.argv[1], sys.argv[2], sys.argv[3]
    keep = sys.argv[4] if len(sys.argv) > 4 else None
    if not os.access(CHROMIUM, os.X_OK):
        skip(f"{CHROMIUM} is absent (apt-get install chromium; scripts/install-deps.sh --tests installs it)")
    try:
        from PIL import Image
    except ImportError:
        skip("PIL is absent (apt-get install python3-pil) to read the screenshot")
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

    dom = subprocess.run([CHROMIUM, *FLAGS, "--virtual-time-budget=5000", "--dump-dom", url], capture_output=True,
                         text=True, timeout=120)
    plots = re.search(r'<body[^>]*data-plots="(\d+)"', dom.stdout)
    drawn = re.search(r'<body[^>]*data-drawn="(\d+)/(\d+)"', dom.stdout)
    if plots is None or drawn is None:
        fail(f"the page's DOM has no data-plots or data-drawn (chromium exit {dom.returncode}):\n{dom.stderr[-3000:]}")
    n = int(plots.group(1))
    if n != 4 or n_img != n:
        fail(f"{n} plots, {n_img} <img> elements; expected 4 (3 series and the verdict grid)")
    if drawn.group(1) != drawn.group(2) or int(drawn.group(2)) != n:
        fail(f"{drawn.group(1)} of {drawn.group(2)} images drawn; expected all {n}")
    errors = [line for line in dom.stderr.splitlines() if "CONSOLE" in line or "Refused to" in line]
    if errors:
        fail("console errors:\n" + "\n".join(errors))

    png = os.path.join(work, "shot.png")
    shot = subprocess.run([CHROMIUM, *FLAGS, f"--screenshot={png}", url], capture_output=True, text=True, timeout=120)
    if not os.path.exists(png):
        fail(f"no screenshot (chromium exit {shot.returncode}):\n{shot.stderr[-3000:]}")
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
