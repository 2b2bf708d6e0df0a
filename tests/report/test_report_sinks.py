"""The report's sinks (issue 68): text from a bench result reaches report.md, index.html and
the CSV files escaped for each and bounded, run by ctest (`report.sinks`).

- report.md's "> Sweep" and "> Machine" lines: Markdown escaped (no raw link, image, HTML or
  added table row from a name, a description, the CPU or the host).
- index.html: no tag or attribute from data.
- CSV (`--csv DIR`): a text cell beginning with = + - @ TAB or CR is behind an apostrophe;
  numbers (negative ones too) stay numbers.
- A 60,000-character description is cut to 4,096 characters with its length said.
"""
import csv
import json
import os
import re
import subprocess

import pytest

SRC = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.environ.get("OCTOCD_BIN", os.path.join(SRC, "build", "octocd"))
RESULT = os.path.join(SRC, "tests", "data", "bench-small-table6.json")

if not os.access(BIN, os.X_OK):
    pytest.skip(f"the octocd CLI is not built at {BIN} (set OCTOCD_BIN)", allow_module_level=True)

HOSTILE = {
    "description": "<script>alert(1)</script> [x](javascript:alert(1)) ![i](http://evil.example/p.png)\n| forged | row |",
    "cpu": "<img src=x onerror=alert(1)>",
    "hostname": "=HYPERLINK(\"http://evil.example\",\"x\")\r\n# heading",
}


def hostile_result(tmp_path, description=HOSTILE["description"]):
    d = json.load(open(RESULT))
    d["sweep"]["description"] = description
    d["sweep"]["definition"]["description"] = description
    d["machine"]["cpu"] = HOSTILE["cpu"]
    d["machine"]["hostname"] = HOSTILE["hostname"]
    for p in d["points"]:
        if p.get("params", {}).get("scene") == "bunny-random-400":
            p["params"]["scene"] = "=cmd|' /C calc'!A0"
    p = tmp_path / "hostile.json"
    p.write_text(json.dumps(d))
    return p


def run_report(tmp_path, result):
    out, csvdir = tmp_path / "out", tmp_path / "csv"
    r = subprocess.run([BIN, "report", str(result), "-o", str(out), "--csv", str(csvdir)], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, (r.returncode, r.stderr)
    return out, csvdir


def test_sweep_and_machine_lines_are_markdown_escaped(tmp_path):
    out, _ = run_report(tmp_path, hostile_result(tmp_path))
    md = (out / "report.md").read_text()
    quoted = [ln for ln in md.splitlines() if ln.startswith("> ")]
    sweep = [ln for ln in quoted if ln.startswith("> Sweep")]
    machine = [ln for ln in quoted if ln.startswith("> Machine")]
    assert len(sweep) == 1 and len(machine) == 1, quoted
    for ln in sweep + machine:
        assert not re.search(r"(?<!\\)<[A-Za-z/]", ln), ln  # no raw tag
        assert not re.search(r"(?<!\\)\]\(", ln), ln  # no link or image target
        assert "![" not in ln, ln  # no image
    assert "\\<script>" in sweep[0] and "\\<img" in machine[0]
    # The description's newline did not add a table row or a heading.
    assert not any(ln.startswith("| forged") for ln in md.splitlines())
    assert not any(ln.startswith("# heading") for ln in md.splitlines())


def test_index_html_holds_no_tag_from_data(tmp_path):
    out, _ = run_report(tmp_path, hostile_result(tmp_path))
    page = (out / "index.html").read_text()
    assert "<script" not in page and "<img" not in page
    assert "&lt;script&gt;" in page and "&lt;img src=x onerror=alert(1)&gt;" in page


def test_csv_text_cells_never_begin_a_formula(tmp_path):
    _, csvdir = run_report(tmp_path, hostile_result(tmp_path))
    files = [f for f in os.listdir(csvdir) if f.endswith(".csv")]
    assert files
    seen_guarded = seen_negative_or_number = 0
    for name in files:
        with open(csvdir / name, newline="") as f:
            for row in csv.reader(f):
                for cell in row:
                    if cell[:1] in ("=", "+", "-", "@", "\t", "\r"):
                        float(cell)  # only a number may begin so
                        seen_negative_or_number += 1
                    if cell.startswith("'=cmd"):
                        seen_guarded += 1
    assert seen_guarded > 0


def test_a_long_description_is_cut_with_its_length_said(tmp_path):
    out, _ = run_report(tmp_path, hostile_result(tmp_path, description="A" * 60000))
    md = (out / "report.md").read_text()
    html = (out / "index.html").read_text()
    assert "... (60,000 characters)" in md and "... (60,000 characters)" in html
    text = re.sub(r"<svg.*?</svg>", "", html, flags=re.S)  # the page's text, the plots aside
    assert len(md) < 200_000 and len(text) < 200_000, (len(md), len(text))


def test_a_failed_first_report_leaves_no_empty_folder(tmp_path):
    """Before: a report that failed on a full disk left an empty plots/ folder (and -o's
    folder made for it); now the folders the failed write made are removed again."""
    import resource

    def limit():  # a file-size limit below the report's files: write() fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))
    out = tmp_path / "out"
    r = subprocess.run([BIN, "report", RESULT, "-o", str(out)], capture_output=True, text=True, timeout=300,
                       preexec_fn=limit)
    assert r.returncode == 1 and "EFBIG" in r.stderr, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr
    left = [str(p) for p in out.rglob("*")] if out.exists() else []
    assert left == [], left
    assert not (out / "plots").exists()
