"""The performance gate beside bench's time budget (docs/bench-format.md "Time budget"): a point
whose runs timed other frames (the budget cut their windows differently) gets no verdict
(exit 2 naming it), however its steps/s compare; the same frames on both sides decide as before.
Run by ctest (`report.gate`): OCTOCD_BIN is the octocd binary."""
import copy
import json
import os
import subprocess

SRC = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DATA = os.path.join(SRC, "tests", "data")
BIN = os.environ.get("OCTOCD_BIN", os.path.join(SRC, "build", "octocd"))


def load(name):
    with open(os.path.join(DATA, name)) as f:
        return json.load(f)


def gate(tmp_path, base, new):
    paths = []
    for name, j in (("base.json", base), ("new.json", new)):
        p = tmp_path / name
        p.write_text(json.dumps(j))
        paths.append(str(p))
    r = subprocess.run([BIN, "report", "--baseline", paths[0], "-o", str(tmp_path / "out"), paths[1]],
                       capture_output=True, text=True, timeout=120)
    return r.returncode, r.stdout, r.stderr


def test_points_timed_over_other_frames_get_no_verdict(tmp_path):
    base = load("gate-base.json")
    same = copy.deepcopy(base)
    same["build"]["build_id"] = "0.1.0+same"
    code, out, err = gate(tmp_path, base, same)
    assert code == 0, out + err  # the same frames: a verdict, as before
    cut = copy.deepcopy(same)
    w = cut["points"][1]["windows"]["all"]
    w["last"] = w["first"] + (w["last"] - w["first"]) // 2  # cut to half its frames, figures unchanged
    w["frames"] = w["last"] - w["first"] + 1
    code, out, err = gate(tmp_path, base, cut)
    assert code == 2, out + err
    assert f"no verdict: '{base['points'][1]['id']}' was timed over other frames" in err, err
    assert "--protocol paper" in err, err
