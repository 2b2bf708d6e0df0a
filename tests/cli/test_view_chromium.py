#!/usr/bin/python3
"""`octocd view`'s page in headless Chromium (design.md section 16): it loads without a console error
and draws (a screenshot that is not blank).

Usage: test_view_chromium.py OCTOCD_BIN SOURCE_DIR WORK_DIR

Steps: Bullet with rotation runs rot-stack-10 for 30 frames into a version 2 trace (every
state, manifold contacts with points); `octocd view` writes the page of pair (1, 2) at
frame 20; Debian's chromium loads it twice, headless (software WebGL): --dump-dom gives the
page's own record of errors (<pre id="octocd-errors">: window errors and console.error) and
its status (<body data-status="drawn"> once the first frame is rendered), and the browser's
log must hold no uncaught error; --screenshot gives the pixels, which must show the scene:
enough pixels away from the background, in many colours, right of the text panel.
Exit 0 pass, 1 fail, 77 skipped (no chromium, or no PIL to read the screenshot).
"""
import os
import re
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from headless_chromium import BASE_FLAGS, dump_dom, fail, require, screenshot  # noqa: E402

FLAGS = [*BASE_FLAGS, "--enable-unsafe-swiftshader", "--window-size=1000,700"]


def main():
    octocd, source, work = sys.argv[1], sys.argv[2], sys.argv[3]
    Image = require()
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    trace = os.path.join(work, "rot-stack.h5")
    subprocess.run([octocd, "run", os.path.join(source, "datasets/scenes/rot-stack-10.json"), "--engine", "bullet",
                    "--rotation", "--frames", "30", "--state-every", "1", "--contacts", "--trace", trace,
                    "--no-xdmf"], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    out = subprocess.run([octocd, "view", trace, "--frame", "20", "--pair", "1,2", "-o", work], check=True,
                         capture_output=True, text=True).stdout
    page = os.path.join(work, "view-f20-pair-1-2.html")
    if not os.path.exists(page):
        fail(f"no page written: {out}")
    url = "file://" + os.path.abspath(page)

    dom = dump_dom(url, FLAGS)
    status = re.search(r'<body[^>]*data-status="([a-z]+)"', dom.stdout)
    errors = re.search(r'<pre id="octocd-errors">(.*?)</pre>', dom.stdout, re.S)
    uncaught = [line for line in dom.stderr.splitlines() if "CONSOLE" in line and "Uncaught" in line]
    if errors is None or status is None:
        fail(f"the page's DOM has no status or error record (chromium exit {dom.returncode}):\n{dom.stderr[-3000:]}")
    if errors.group(1).strip():
        fail(f"console errors on the page: {errors.group(1).strip()}")
    if uncaught:
        fail("uncaught errors in the browser log:\n" + "\n".join(uncaught))
    if status.group(1) != "drawn":
        fail(f"the page's status is '{status.group(1)}', not 'drawn'")

    png = os.path.join(work, "shot.png")
    shot = screenshot(url, png, FLAGS)
    uncaught = [line for line in shot.stderr.splitlines() if "CONSOLE" in line and "Uncaught" in line]
    if uncaught:
        fail("uncaught errors in the browser log:\n" + "\n".join(uncaught))
    image = Image.open(png).convert("RGB")
    width, height = image.size
    # The scene right of the text panel (420 px wide), against the background #f4f4f2.
    region = image.crop((430, 0, width, height))
    pixels = list(region.getdata())
    background = (0xf4, 0xf4, 0xf2)
    away = sum(1 for p in pixels if max(abs(p[k] - background[k]) for k in range(3)) > 24)
    colours = len(set(pixels))
    share = away / len(pixels)
    print(f"page {os.path.getsize(page)} bytes; screenshot {width}x{height}: {share:.1%} of the scene's pixels "
          f"away from the background, {colours} colours")
    if share < 0.05 or colours < 32:
        fail(f"the screenshot is blank: {share:.1%} of the pixels away from the background, {colours} colours")
    print("PASS")


if __name__ == "__main__":
    main()
