#!/usr/bin/python3
"""Every `--help` on stdout within 100 characters a line (issue 80 item 6; docs/cli.md keeps
the details): `octocd --help`, each subcommand's it lists (and theirs, should they list any),
and the scripts that take --help (scripts/nightly.sh, scripts/gpu-bundle.sh); `octocd
validate --help`, the longest, within 60 lines (each option a line or two).

Usage: test_help.py OCTOCD_BIN SOURCE_DIR
Each must exit 0 with its help on stdout and nothing on stderr; a line over 100 characters
is named with its command. Exit 0 pass, 1 fail.
"""
import os
import re
import subprocess
import sys

WIDTH = 100
MOST_LINES = {"octocd validate": 60}  # help whose details live in docs/cli.md


def main():
    octocd, source = sys.argv[1], sys.argv[2]
    problems, seen = [], []

    def check(argv, label):
        run = subprocess.run([*argv, "--help"], capture_output=True, text=True, timeout=60)
        seen.append(label)
        if run.returncode != 0:
            problems.append(f"{label} --help: exit {run.returncode}")
        if run.stderr:
            problems.append(f"{label} --help: {len(run.stderr)} characters on stderr: {run.stderr[:200]!r}")
        if not run.stdout.strip():
            problems.append(f"{label} --help: nothing on stdout")
        lines = run.stdout.splitlines()
        if len(lines) > MOST_LINES.get(label, len(lines)):
            problems.append(f"{label} --help: {len(lines)} lines; at most {MOST_LINES[label]} (details: docs/cli.md)")
        for n, line in enumerate(lines, 1):
            if len(line) > WIDTH:
                problems.append(f"{label} --help line {n}: {len(line)} characters: {line[:120]}...")
        return run.stdout

    def walk(path):
        text = check([octocd, *path], " ".join(["octocd", *path]))
        listed = text.split("\nSubcommands:\n", 1)
        if len(listed) == 2:
            for line in listed[1].splitlines():
                m = re.match(r"^  ([a-z][a-z-]*)\s", line)
                if not m:
                    break
                walk([*path, m.group(1)])

    walk([])
    for script in ("scripts/nightly.sh", "scripts/gpu-bundle.sh"):
        check(["bash", os.path.join(source, script)], script)
    print(f"{len(seen)} helps checked: {', '.join(seen)}")
    if len(seen) < 10:
        problems.append(f"only {len(seen)} helps found; octocd --help lists fewer subcommands than expected")
    if problems:
        print("FAIL:\n" + "\n".join(problems))
        sys.exit(1)
    print("PASS")


if __name__ == "__main__":
    main()
