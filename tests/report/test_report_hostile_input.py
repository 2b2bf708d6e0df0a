"""`octocd report` on untrusted input (issue 36), run by ctest (`report.inputs.corpus`:
the fuzz corpus; `report.inputs`: the rest).

- Traces reach the report only through `octocd trace-summary --json` (the hardened reader):
  external storage is refused naming file and dataset (exit 2, one line, no traceback),
  rows past committed_frames are never shown, and the fuzz corpus (fuzz/regressions/trace)
  never crashes or hangs the report.
- An output folder (-o, --csv) that is a file, /dev/null, a symbolic link (to /etc) or a
  read-only folder is exit 2 with one line naming the option.
- A rerun into the same folder that fails on a full disk (here: a file-size limit) leaves
  the earlier report's files byte for byte, and no temporary file.
- SIGTERM / SIGINT to octocd end the script it runs (forwarded, waited for): the script is
  a stub that says "started" with its pid and waits; the signal is sent after that line.
Inputs are generated here (traces from `octocd run`, 20-40 frames of box-stack).
"""
import os
import resource
import signal
import stat
import subprocess
import sys

import pytest

SRC = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.environ.get("OCTOCD_BIN", os.path.join(SRC, "build", "octocd"))
SCENE = os.path.join(SRC, "datasets", "scenes", "box-stack.json")
CORPUS = os.path.join(SRC, "fuzz", "regressions", "trace")
RESULT = os.path.join(SRC, "tests", "data", "bench-small-table6.json")

if not os.access(BIN, os.X_OK):
    pytest.skip(f"the octocd CLI is not built at {BIN} (set OCTOCD_BIN)", allow_module_level=True)
h5py = pytest.importorskip("h5py", reason="python3-h5py is not installed (the tests edit traces with it)")


def trace(tmp_path, name="t.h5", frames=30):
    p = str(tmp_path / name)
    subprocess.run([BIN, "run", SCENE, "--frames", str(frames), "--trace", p, "--quiet", "--no-xdmf"], check=True)
    return p


def report(*args, **kw):
    return subprocess.run([BIN, "report"] + [str(a) for a in args], capture_output=True, text=True, timeout=300, **kw)


def one_line_error(r, code=2):
    assert r.returncode == code, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr, r.stderr


def test_a_trace_with_external_storage_is_refused_naming_file_and_dataset(tmp_path):
    t = trace(tmp_path)
    secret = tmp_path / "passwd"
    secret.write_bytes(b"root:x:0:0:root:/root:/bin/bash\n" * 64)
    with h5py.File(t, "r+") as f:
        n = f["frames/kinetic_energy"].shape[0]
        del f["frames/kinetic_energy"]
        f.create_dataset("frames/kinetic_energy", shape=(n,), dtype="f8", external=[(str(secret), 0, 8 * n)])
    r = report(t, "-o", tmp_path / "out")
    one_line_error(r)
    assert f"{t}: /frames/kinetic_energy: external storage (raw data kept in another file), refused" in r.stderr
    assert not (tmp_path / "out" / "report.md").exists()


def test_rows_past_committed_frames_are_never_shown(tmp_path):
    t = trace(tmp_path, frames=30)
    with h5py.File(t, "r+") as f:
        f.attrs["committed_frames"] = 20  # as a failed write leaves it: 30 rows on disk, 20 committed
    r = report(t, "-o", tmp_path / "out")
    assert r.returncode == 0, r.stderr
    md = (tmp_path / "out" / "report.md").read_text()
    assert "box-stack" in md and ", 20 frames;" in md and ", 30 frames;" not in md


def test_the_fuzz_corpus_never_crashes_or_hangs_the_report(tmp_path):
    for name in sorted(os.listdir(CORPUS)):
        p = os.path.join(CORPUS, name)
        r = report(p, "-o", tmp_path / name)
        assert r.returncode in (0, 2), (name, r.returncode, r.stderr)
        assert "Traceback" not in r.stderr and "killed" not in r.stderr, (name, r.stderr)
        if r.returncode == 2:
            assert p in r.stderr, (name, r.stderr)
    r = report(os.path.join(CORPUS, "flip-global-heap-oversize-segv.h5"), "-o", tmp_path / "x")
    assert r.returncode == 2 and "flip-global-heap-oversize-segv.h5: corrupt file" in r.stderr


def test_a_fifo_input_is_refused(tmp_path):
    fifo = tmp_path / "pipe.h5"
    os.mkfifo(fifo)
    r = report(fifo, "-o", tmp_path / "out")
    one_line_error(r)
    assert f"{fifo}: not a regular file (a FIFO)" in r.stderr


@pytest.mark.parametrize("option", ["-o", "--csv"])
def test_output_folders_that_are_not_writable_folders_are_refused(tmp_path, option):
    a_file = tmp_path / "file"
    a_file.write_text("x")
    link = tmp_path / "etc-link"
    link.symlink_to("/etc")
    ro = tmp_path / "read-only"
    ro.mkdir()
    ro.chmod(0o555)
    cases = [(a_file, "a file, not a folder"), ("/dev/null", "a device, not a folder"),
             (link, "a symbolic link (to /etc)"), (ro, "a read-only folder")]
    for path, why in cases:
        args = [RESULT, "-o", tmp_path / "out"] if option == "--csv" else [RESULT]
        r = report(*args, option, path) if option == "--csv" else report(*args, "-o", path)
        one_line_error(r)
        assert f"{option} {path}: {why}" in r.stderr, r.stderr
    assert not os.path.exists("/etc/index.html") and not os.path.exists("/etc/report.md")
    assert a_file.read_text() == "x" and os.listdir(ro) == []


def test_a_rerun_on_a_full_disk_leaves_the_earlier_report(tmp_path):
    t = trace(tmp_path)
    out, csv = tmp_path / "out", tmp_path / "csv"
    r = report(RESULT, t, "-o", out, "--csv", csv)
    assert r.returncode == 0, r.stderr
    before = {p: p.read_bytes() for d in (out, csv) for p in sorted(d.rglob("*")) if p.is_file()}
    assert any(p.suffix == ".svg" for p in before) and any(p.suffix == ".csv" for p in before)

    def limit():  # a file-size limit below the report's files: write() fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))
    r = report(RESULT, t, "-o", out, "--csv", csv, "--title", "second", preexec_fn=limit)
    one_line_error(r, code=1)
    assert "EFBIG" in r.stderr and "the earlier report (if any) is left as it was" in r.stderr, r.stderr
    after = {p: p.read_bytes() for d in (out, csv) for p in sorted(d.rglob("*")) if p.is_file()}
    assert after == before  # every file byte for byte, no temporary file left


STUB = """import os, signal, sys
print("started", os.getpid(), flush=True)
signal.pause()
"""


@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_to_octocd_ends_the_report_script_too(tmp_path, sig, code):
    stub = tmp_path / "stub.py"
    stub.write_text(STUB)
    env = dict(os.environ, OCTOCD_REPORT_SCRIPT=str(stub))
    p = subprocess.Popen([BIN, "report", RESULT, "-o", str(tmp_path / "out")], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=env)
    try:
        word, pid = p.stdout.readline().split()
        assert word == "started"
        p.send_signal(sig)
        assert p.wait(timeout=30) == code, p.stderr.read()
        with pytest.raises(ProcessLookupError):  # the script ended and octocd reaped it
            os.kill(int(pid), 0)
        assert f"report stopped by {signal.Signals(sig).name}" in p.stderr.read()
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()


def test_markdown_in_a_trace_and_links_planted_at_report_files(tmp_path):
    """Issue 57. Before: a trace's scene name went into report.md as written (a Markdown link,
    an image, a table cell break), and each report file was staged as .NAME.tmp.PID: a link
    planted there (or at the file) was followed. Now the text is escaped and the temporary
    name is unpredictable (mkstemp); a link at a report file's own path is exit 2."""
    t = trace(tmp_path)
    with h5py.File(t, "r+") as f:
        f.attrs["scene_name"] = "evil](http://x.invalid/) ![i](http://x.invalid/p.png) | cell <b>"
    out = tmp_path / "out"
    r = report(t, "-o", out)
    assert r.returncode == 0, r.stderr
    md = (out / "report.md").read_text()
    for text in ("](http://x.invalid/", "[i]", "<b>", "| cell"):  # no link, image, tag or cell from the trace
        assert md.count(text) == md.count("\\" + text), (text, md)
    assert r"evil\](http://x.invalid/) !\[i\](http://x.invalid/p.png) \| cell \<b>" in md, md
    # A rerun with links planted at the old predictable temporary names follows none of them.
    victim = tmp_path / "victim"
    victim.write_text("precious\n")
    script = (f"for f in index.html report.md; do ln -s {victim} {out}/.$f.tmp.$$; done; "
              f"exec {BIN} report {t} -o {out}")
    r = subprocess.run(["sh", "-c", script], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert victim.read_text() == "precious\n"
    # A link at report.md itself is refused, naming it; the link and its target stay.
    for name in os.listdir(out):
        if os.path.islink(out / name):
            os.unlink(out / name)
    os.unlink(out / "report.md")
    os.symlink(victim, out / "report.md")
    r = report(t, "-o", out)
    one_line_error(r)
    assert f"{out}/report.md: a symbolic link, not a regular file" in r.stderr, r.stderr
    assert victim.read_text() == "precious\n" and os.path.islink(out / "report.md")
