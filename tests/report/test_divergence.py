"""The report's divergence section (issue 70 item 2; report/report_divergence.py) on a result of
`octocd bench tests/data/bench-small-divergence.json` (two free-falling boxes and box-stack, cpu,
40 frames): one log-scale plot per scene, a table of exponents per scene with the free fall's
exponent ~0, the CSV with a row per frame of every point, and a malformed point refused with
exit 2 naming it. Run by ctest (`report.readable`)."""
import csv
import json
import os
import subprocess
import sys

import pytest

SRC = os.environ.get("OCTOCD_SOURCE_DIR") or os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__))))
BIN = os.environ.get("OCTOCD_BIN")
REPORT = os.path.join(SRC, "report", "make_report.py")


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    if not BIN or not os.access(BIN, os.X_OK):
        pytest.skip("OCTOCD_BIN not set: needs the octocd binary (ctest sets it)")
    d = tmp_path_factory.mktemp("div")
    out = d / "d.json"
    r = subprocess.run([BIN, "bench", os.path.join(SRC, "tests", "data", "bench-small-divergence.json"), "-o",
                        str(out), "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    return out


def report(inputs, out, csv_dir=None):
    cmd = [sys.executable, REPORT, "-o", str(out)] + (["--csv", str(csv_dir)] if csv_dir else []) + \
        [str(x) for x in inputs]
    return subprocess.run(cmd, capture_output=True, text=True)


def test_one_log_plot_per_scene_and_the_exponents(result, tmp_path):
    r = report([result], tmp_path / "rep", tmp_path / "csv")
    assert r.returncode == 0, r.stdout + r.stderr
    plots = sorted(os.listdir(tmp_path / "rep" / "plots"))
    assert [p.split("-", 1)[1] for p in plots] == ["divergence-sa-free-fall.svg", "divergence-box-stack.svg"]
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "### sa-free-fall" in md and "### box-stack" in md
    # The free fall's exponents (eps > 0) are ~0 in the table; eps 0 has none, with its reason.
    rows = [line.split("|") for line in md.splitlines() if line.startswith("| cpu |")]
    free = rows[:4]
    assert free[0][2].strip() == "0" and free[0][7].strip().startswith("- (")
    for row in free[1:]:
        assert abs(float(row[7])) < 0.05, row
    for svg in plots:  # a log axis: matplotlib writes its ticks as 10^k
        text = (tmp_path / "rep" / "plots" / svg).read_text()
        assert "<svg" in text
    with open(tmp_path / "csv" / "small-divergence.csv") as f:
        data = list(csv.DictReader(f))
    assert len(data) == 8 * 41
    assert {d["scene"] for d in data} == {"sa-free-fall", "box-stack"}
    zero = [d for d in data if float(d["eps [m]"]) == 0.0]
    assert zero and all(float(d["mean_distance [m]"]) == 0.0 for d in zero)


def test_a_malformed_point_is_refused(result, tmp_path):
    j = json.loads(result.read_text())
    j["points"][1]["mean_m"][3] = "far"
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(j))
    r = report([bad], tmp_path / "rep")
    assert r.returncode == 2, r.stdout + r.stderr
    assert "points[1].mean_m" in r.stderr
