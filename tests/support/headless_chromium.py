"""Headless Chromium for the page tests (tests/cli/test_view_chromium.py,
tests/report/test_report_chromium.py, tests/report/test_history_chromium.py): the
skip/fail protocol of a ctest script (exit 77 skipped, 1 failed), the checks that Debian's
chromium and PIL are present, a page's DOM after its scripts ran, and a screenshot.
"""
import os
import subprocess
import sys

CHROMIUM = "/usr/bin/chromium"
# Flags every page test passes; each adds its window size (and WebGL's software renderer).
BASE_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--enable-logging=stderr", "--hide-scrollbars"]


def skip(reason):
    """Ends the test as skipped (ctest's SKIP_RETURN_CODE 77), saying why."""
    print(f"SKIPPED: {reason}")
    sys.exit(77)


def fail(reason):
    """Ends the test as failed (exit 1), saying why."""
    print(f"FAIL: {reason}")
    sys.exit(1)


def require():
    """Skips unless chromium and PIL are present; returns PIL's Image module."""
    if not os.access(CHROMIUM, os.X_OK):
        skip(f"{CHROMIUM} is absent (apt-get install chromium; scripts/install-deps.sh --tests installs it)")
    try:
        from PIL import Image
    except ImportError:
        skip("PIL is absent (apt-get install python3-pil) to read the screenshot")
    return Image


def dump_dom(url, flags):
    """The page's DOM after 5 s of virtual time (its load handlers ran): a CompletedProcess
    whose stdout is the DOM and stderr the browser's log."""
    return subprocess.run([CHROMIUM, *flags, "--virtual-time-budget=5000", "--dump-dom", url], capture_output=True,
                          text=True, timeout=120)


def screenshot(url, png, flags):
    """Writes the page's screenshot to `png` (fails the test when none is written); returns
    the CompletedProcess (stderr: the browser's log)."""
    shot = subprocess.run([CHROMIUM, *flags, f"--screenshot={png}", url], capture_output=True, text=True, timeout=120)
    if not os.path.exists(png):
        fail(f"no screenshot (chromium exit {shot.returncode}):\n{shot.stderr[-3000:]}")
    return shot


def console_errors(log):
    """The lines of a browser log that report a console message or a refused load."""
    return [line for line in log.splitlines() if "CONSOLE" in line or "Refused to" in line]
