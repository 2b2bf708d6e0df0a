#!/usr/bin/python3
"""Fuzz the bench-result JSON that report/make_report.py reads (issue 36, the report's input).

    /usr/bin/python3 scripts/fuzz_report_json.py SECONDS|runs=N WORK_DIR OCTOCD_BIN SEED.json...

make_report.py is Python (no libFuzzer, no sanitizer applies): this driver runs its run()
(main() and the handlers that turn a failure into one line and an exit code) in this interpreter, as `octocd report RESULT.json -o DIR` runs it, on structure-aware
mutations of the seed results (a value replaced by another type, a huge or negative number,
NaN or Infinity, a non-ASCII or empty string, a key deleted, a list emptied or an element
repeated, a subtree copied elsewhere; now and then the text itself cut or a byte flipped).
Outcomes allowed: exit 0 (a report) or exit 2 (a refusal naming the file and key). Anything
else (a traceback, exit 1, another exit code, a report whose index.html is missing) is a
finding: its input goes to WORK_DIR/artifacts/ with the traceback. Feedback: an input joins
the corpus when it reaches a line of make_report.py no input reached before (a line tracer
on that file only). Each seed first runs as it is (ctest replays fuzz/regressions/report-json/
so, with runs=N: N mutations, the same ones every time). Prints the executions, corpus size,
lines covered and findings; exit 1 on a finding.
"""
import copy
import json
import math
import os
import random
import shutil
import sys
import time
import traceback

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.normpath(os.path.join(HERE, "..", "report")))
import make_report  # noqa: E402  (matplotlib loaded once)

MR = os.path.dirname(os.path.abspath(make_report.__file__))  # make_report.py and its report_*.py modules
LINES = set()


def line_tracer(frame, event, arg):
    if event == "line":
        LINES.add((frame.f_code.co_filename, frame.f_lineno))
    return line_tracer


def global_tracer(frame, event, arg):
    f = frame.f_code.co_filename
    return line_tracer if os.path.dirname(os.path.abspath(f)) == MR and os.path.basename(f).endswith(".py") else None


WEIRD = [None, True, False, 0, -1, 1, 2 ** 63, -(2 ** 63), 10 ** 30, 1e308, -1e308, 1e-320, 0.5, float("nan"),
         float("inf"), -float("inf"), "", "x", "ok", "skipped", "failed", "cpu", "\u00e9\u4e2d\U0001F600", "a" * 5000,
         [], [1], [None], {}, {"median": 1}, {"n": 1, "median": 1, "min": 1, "max": 1}]


def paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from paths(v, prefix + (i,))


def get(node, path):
    for p in path:
        node = node[p]
    return node


def mutate(doc, rng):
    doc = copy.deepcopy(doc)
    all_paths = list(paths(doc))
    for _ in range(rng.randint(1, 3)):
        path = rng.choice(all_paths)
        if not path:
            continue
        try:
            parent, key = get(doc, path[:-1]), path[-1]
            op = rng.randrange(6)
            if op == 0:
                parent[key] = rng.choice(WEIRD)
            elif op == 1 and isinstance(parent, dict):
                del parent[key]
            elif op == 2:
                parent[key] = copy.deepcopy(get(doc, rng.choice(all_paths)))
            elif op == 3 and isinstance(parent[key], list):
                parent[key] = parent[key][: rng.randrange(len(parent[key]) + 1)]
                if parent[key] and rng.random() < 0.5:
                    parent[key].append(copy.deepcopy(rng.choice(parent[key])))
            elif op == 4 and isinstance(parent[key], (int, float)) and not isinstance(parent[key], bool):
                parent[key] = rng.choice([-parent[key], parent[key] * 1e6, parent[key] + 1, 0])
            elif op == 5 and isinstance(parent, dict):
                parent[rng.choice(["id", "status", "params", "windows", "ms_per_frame", "x" + str(rng.random())])] = \
                    rng.choice(WEIRD)
        except (KeyError, IndexError, TypeError):
            pass
        all_paths = list(paths(doc))
    return doc


def as_text(doc, rng):
    text = json.dumps(doc, allow_nan=True)
    if rng.random() < 0.05:
        text = text[: rng.randrange(len(text) + 1)]
    elif rng.random() < 0.05 and text:
        i = rng.randrange(len(text))
        text = text[:i] + chr(rng.randrange(1, 256)) + text[i + 1:]
    return text


def run_once(path, out, octocd):
    """make_report's run() (what `python3 make_report.py` runs) on one input: its exit code,
    or the traceback of an exception it let through."""
    sys.argv = ["make_report.py", "-o", out, "--octocd", octocd, path]
    code = 0
    try:
        make_report.run()
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else 1
    except Exception:  # noqa: BLE001  a finding
        return None, traceback.format_exc()
    finally:
        make_report.plt.close("all")
    return code, ""


def main():
    budget, work, octocd, seeds = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4:]
    seeds = [s for s in seeds if os.path.isfile(s)]  # an empty regressions folder's glob left as it is
    runs_only = int(budget[5:]) if budget.startswith("runs=") else None
    seconds = float("inf") if runs_only is not None else float(budget)
    rng = random.Random(36)
    os.makedirs(os.path.join(work, "artifacts"), exist_ok=True)
    corpus = []
    for s in seeds:
        try:
            corpus.append(json.load(open(s)))
        except ValueError:  # a regression input that is not JSON: run as text, not mutated
            pass
    path, out = os.path.join(work, "input.json"), os.path.join(work, "out")
    devnull = open(os.devnull, "w")
    runs = findings = 0
    outcomes = {}
    t0 = time.monotonic()
    pending = list(seeds)  # each seed (and regression input) once as it is
    while pending or (time.monotonic() - t0 < seconds and (runs_only is None or runs < runs_only + len(seeds))):
        if pending:
            doc = None
            shutil.copy(pending.pop(0), path)
        else:
            doc = mutate(rng.choice(corpus), rng)
            with open(path, "w") as f:
                f.write(as_text(doc, rng))
        shutil.rmtree(out, ignore_errors=True)
        before = len(LINES)
        saved = sys.stdout, sys.stderr
        sys.stdout = sys.stderr = devnull
        sys.settrace(global_tracer)
        try:
            code, tb = run_once(path, out, octocd)
        finally:
            sys.settrace(None)
            sys.stdout, sys.stderr = saved
        runs += 1
        if code == 0 and not os.path.exists(os.path.join(out, "index.html")):
            code, tb = None, "exit 0 without index.html"
        if code not in (0, 2):
            findings += 1
            name = os.path.join(work, "artifacts", f"finding-{findings}.json")
            shutil.copy(path, name)
            with open(name + ".txt", "w") as f:
                f.write(tb or f"exit {code}")
            print(f"finding {findings}: {name}: {(tb or f'exit {code}').strip().splitlines()[-1]}", flush=True)
        else:
            outcomes[code] = outcomes.get(code, 0) + 1
            if len(LINES) > before and doc is not None:
                corpus.append(doc)
    print(f"stat::number_of_executed_units: {runs}")
    print(f"stat::corpus_size: {len(corpus)} ({len(seeds)} seeds)")
    print(f"stat::lines_covered: {len(LINES)} of make_report.py and its report_*.py modules")
    print(f"stat::outcomes: " + ", ".join(f"exit {k}: {v}" for k, v in sorted(outcomes.items())))
    print(f"stat::findings: {findings}")
    return 1 if findings else 0


if __name__ == "__main__":
    sys.exit(main())
