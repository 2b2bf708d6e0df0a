#!/usr/bin/python3
"""`validate --view`'s pages of two failures in headless Chromium (design.md section 16, issue 80
items 4 and 8): a DART friction-cone failure and a MuJoCo normal-angle failure, and a trace
without contact rows.

Usage: test_view_failures_chromium.py OCTOCD_BIN SOURCE_DIR WORK_DIR [IMAGES_DIR]

Steps:
- DART runs rot-drop-220 for 60 frames (`validate --view`, the quick matrix's window): the
  friction row fails on pair (2, 176) at frame 1, 1.337x the cone. Its page's panel (the DOM
  after the page's script ran) must write the friction rule, |sum jt3|, the cone mu x jn and
  the ratio the validator printed, "outside"; the screenshot must show the friction impulse
  (magenta) and the pair's body B (sky blue) beside the panel, not under it.
- MuJoCo runs bunny-stack-50 for 600 frames: contact-geometry fails on pair (0, 8) at frame
  570 (46.1 deg). The panel must write the angle the validator printed and the pair's own
  arrow scale: its deepest row over the window, which is less than the deepest row drawn
  (another pair's arrow would set the scale of every arrow otherwise).
- cpu runs box-stack without --contacts: the page says "this trace has no contact rows".
IMAGES_DIR (optional): the two screenshots are copied there (docs/images, by hand).
Exit 0 pass, 1 fail, 77 skipped (no chromium or PIL, or dart / mujoco not available).
"""
import json
import os
import re
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from headless_chromium import BASE_FLAGS, dump_dom, fail, require, screenshot, skip  # noqa: E402

PANEL_WIDTH = 400  # the page's #panel: the scene lies right of it
FLAGS = [*BASE_FLAGS, "--enable-unsafe-swiftshader", "--window-size=1200,760"]


def validate(octocd, source, scene, engine, frames, every, out):
    """Runs `validate --view out`; returns its stdout (exit 3: the failure is expected)."""
    run = subprocess.run([octocd, "validate", os.path.join(source, "datasets/scenes", scene), "--engine", engine,
                          "--frames", str(frames), "--every", str(every), "--view", out], capture_output=True,
                         text=True)
    if run.returncode != 3:
        fail(f"validate {scene} --engine {engine}: exit {run.returncode}, expected 3 (a failure)\n"
             f"{run.stdout[-2000:]}{run.stderr[-2000:]}")
    return run.stdout


def page_of(stdout, row_cause):
    """The page `validate --view` lists for row/cause: (frame, a, b, path)."""
    m = re.search(rf"^  {re.escape(row_cause)} frame (\d+) pair \((\d+), (\d+)\): (\S+)$", stdout, re.M)
    if not m:
        fail(f"no page of {row_cause} listed:\n{stdout[-3000:]}")
    return int(m.group(1)), int(m.group(2)), int(m.group(3)), m.group(4)


def panel(page):
    """The page's DOM after its script ran: (figures text, scale text); fails on any error."""
    dom = dump_dom("file://" + os.path.abspath(page), FLAGS)
    status = re.search(r'<body[^>]*data-status="([a-z]+)"', dom.stdout)
    errors = re.search(r'<pre id="octocd-errors">(.*?)</pre>', dom.stdout, re.S)
    if status is None or errors is None:
        fail(f"{page}: no status or error record in the DOM (chromium exit {dom.returncode}):\n{dom.stderr[-3000:]}")
    if errors.group(1).strip() or status.group(1) != "drawn":
        fail(f"{page}: status {status.group(1)}, errors: {errors.group(1).strip()}")
    figures = re.search(r'<div id="figures">(.*?)</div>', dom.stdout, re.S)
    scale = re.search(r'<div id="scale">(.*?)</div>', dom.stdout, re.S)
    note = re.search(r'<div id="note">(.*?)</div>', dom.stdout, re.S)
    return figures.group(1), scale.group(1), note.group(1)


def scene_pixels(Image, page, png):
    """The screenshot's pixels right of the panel."""
    screenshot("file://" + os.path.abspath(page), png, FLAGS)
    image = Image.open(png).convert("RGB")
    return list(image.crop((PANEL_WIDTH + 10, 0, image.size[0], image.size[1])).getdata())


def count(pixels, test):
    return sum(1 for p in pixels if test(p))


def main():
    octocd, source, work = sys.argv[1], sys.argv[2], sys.argv[3]
    images = sys.argv[4] if len(sys.argv) > 4 else ""
    Image = require()
    available = subprocess.run([octocd, "engines", "--available"], capture_output=True, text=True).stdout.split()
    for engine in ("dart", "mujoco"):
        if engine not in available:
            skip(f"engine {engine} is not available in this build")
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)

    # A DART friction-cone failure: the ratio the validator printed, on the page.
    out = validate(octocd, source, "rot-drop-220.json", "dart", 60, 5, os.path.join(work, "dart"))
    ratio = re.search(r"friction/cone: .*?\(([0-9.]+) x the cone\)", out)
    if not ratio:
        fail(f"validate printed no friction/cone ratio:\n{out[-3000:]}")
    frame, a, b, page = page_of(out, "friction/cone")
    figures, scale, _ = panel(page)
    for want in ("friction        rule jt3", "|sum jt3|", "cone mu x jn",
                 f"ratio           {ratio.group(1)}x the cone (outside)"):
        if want not in figures:
            fail(f"friction page {page}: '{want}' not in its panel:\n{figures}")
    if f"arrows of pair ({a}, {b})" not in scale:
        fail(f"friction page: the arrow scale is not the pair's: {scale}")
    friction_png = os.path.join(work, "view-friction-dart.png")
    pixels = scene_pixels(Image, page, friction_png)
    magenta = count(pixels, lambda p: p[0] > 180 and p[1] < 60 and 110 < p[2] < 200)
    sky = count(pixels, lambda p: p[2] > 150 and p[2] > p[0] + 50 and p[1] > p[0] + 20)
    print(f"friction page: ratio {ratio.group(1)}x in the panel; beside it {magenta} friction-impulse pixels, "
          f"{sky} sky-blue pixels of body {b}")
    if magenta < 20 or sky < 200:
        fail(f"the friction page's scene shows {magenta} friction-impulse and {sky} body-B pixels "
             "(want >= 20 and >= 200)")

    # A MuJoCo normal-angle failure: the angle, and the pair's own arrow scale.
    out = validate(octocd, source, "bunny-stack-50.json", "mujoco", 600, 10, os.path.join(work, "mujoco"))
    angle = re.search(r"contact-geometry/normal-angle: worst ([0-9.]+) deg", out)
    frame, a, b, page = page_of(out, "contact-geometry/normal-angle")
    figures, scale, _ = panel(page)
    shown = re.search(r"angle +([0-9.]+) deg", figures)
    if not angle or not shown or abs(float(shown.group(1)) - float(angle.group(1))) > 0.01:
        fail(f"normal-angle page: angle {shown and shown.group(1)} against the validator's "
             f"{angle and angle.group(1)}:\n{figures}")
    data = open(page, encoding="utf-8").read()
    doc = re.search(r'<script type="application/json" id="octocd-data">(.*?)</script>', data, re.S).group(1)
    frames = json.loads(doc)["frames"]
    deepest_all = max((c["depth"] for f in frames for c in f["contacts"]), default=0)
    deepest_pair = max(c["depth"] for f in frames for c in f["contacts"] if (c["a"], c["b"]) == (a, b))
    m = re.search(rf"arrows of pair \({a}, {b}\): .*?its deepest ([0-9.e-]+) m", scale)
    if not m or abs(float(m.group(1)) - deepest_pair) > 1e-3 * deepest_pair:
        fail(f"normal-angle page: the arrow scale is not the pair's (deepest {deepest_pair} m): {scale}")
    if not deepest_all > deepest_pair:
        fail(f"the case does not test the per-pair scale: the pair's row is the deepest ({deepest_pair} m)")
    angle_png = os.path.join(work, "view-normal-angle-mujoco.png")
    pixels = scene_pixels(Image, page, angle_png)
    red = count(pixels, lambda p: p[0] > 180 and p[1] < 60 and p[2] < 60)
    green = count(pixels, lambda p: p[1] > 120 and p[0] < 60 and p[2] < 90)
    print(f"normal-angle page: angle {shown.group(1)} deg; the pair's deepest row {deepest_pair:.4g} m against "
          f"{deepest_all:.4g} m drawn; beside the panel {red} red (engine normal) and {green} green (reference) "
          "pixels")
    if red < 20 or green < 20:
        fail(f"the normal-angle page's scene shows {red} engine-normal and {green} reference pixels (want >= 20)")

    # A trace without contact rows says so.
    trace = os.path.join(work, "no-rows.h5")
    subprocess.run([octocd, "run", os.path.join(source, "datasets/scenes/box-stack.json"), "--engine", "cpu",
                    "--frames", "20", "--trace", trace, "--no-xdmf", "--quiet"], check=True,
                   stdout=subprocess.DEVNULL)
    subprocess.run([octocd, "view", trace, "-o", os.path.join(work, "rows")], check=True, stdout=subprocess.DEVNULL)
    pages = [p for p in os.listdir(os.path.join(work, "rows")) if p.endswith(".html")]
    figures, _, note = panel(os.path.join(work, "rows", pages[0]))
    if "this trace has no contact rows" not in figures or "this trace has no contact rows" not in note:
        fail(f"a trace without contact rows: the page does not say so:\n{note}\n{figures}")
    print("no-rows page: says 'this trace has no contact rows'")

    if images:
        for png in (friction_png, angle_png):
            shutil.copy(png, os.path.join(images, os.path.basename(png)))
    print("PASS")


if __name__ == "__main__":
    main()
