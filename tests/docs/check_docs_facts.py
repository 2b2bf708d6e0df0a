#!/usr/bin/python3
"""docs/ against the code where a test can read both (ctest `docs.facts`, issue 80 item 7):

1. Engines: every engine of the registry (`octocd engines --json`) has its section in
   docs/engines.md (`## NAME`; octocd's own cpu and cuda in its opening) and is named where
   docs/bench-format.md lists a sweep's engines (its "Engines:" paragraph and the
   `engines` field's row), since a sweep's default is every engine of the registry.
2. Exit codes: every code `octocd --help` lists under "Exit codes:" is a row of
   docs/cli.md's "Exit codes" table and is named in README.md's "Exit codes:" sentence.
3. The nightly's scene set: scripts/nightly.sh's default set (its `default_set`) names
   shipped scenes (datasets/scenes/NAME.json); docs/validation-output.md and docs/cli.md
   give its size ("default scene set (N scenes"), and docs/validation.md's count of the
   scenes whose conservation row fails without --expect ("fails on K of the N scenes") is
   the count scripts/nightly-expect.json records for it.
4. Tolerances: docs/validation.md's table of the tolerances (`octocd validate --help` sends
   the reader there) has one row `| `NAME` | DEFAULT | UNIT |` per entry of
   validation/include/octocd/tolerances.def, in its order, and no other.

Usage: check_docs_facts.py OCTOCD_BIN SOURCE_DIR. Exit 0 when all hold, 1 naming each page,
the fact and what the code says.
"""
import json
import pathlib
import re
import subprocess
import sys


def main(octocd, root):
    root = pathlib.Path(root).resolve()
    errors = []

    def page(name):
        return (root / name).read_text(encoding="utf-8")

    # 1. Engines.
    engines = [e["name"] for e in json.loads(subprocess.run([octocd, "engines", "--json", "--no-checks"],
                                                            capture_output=True, text=True,
                                                            check=True).stdout)["engines"]]
    if len(engines) < 3:
        errors.append(f"octocd engines --json lists {engines}: too few to check")
    engines_md = page("docs/engines.md")
    opening = engines_md.split("\n## ", 1)[0]
    for e in engines:
        if not re.search(rf"^## {re.escape(e)}$", engines_md, re.M) and f"`{e}`" not in opening:
            errors.append(f"docs/engines.md: engine {e} (octocd engines) has no section '## {e}'")
    bench = page("docs/bench-format.md")
    para = re.search(r"^Engines: (.*?)(?:\n\n|\Z)", bench, re.M | re.S)
    row = re.search(r"^\| `engines` \|[^\n]*$", bench, re.M)
    for label, text in (("its 'Engines:' paragraph", para and para.group(1)), ("the `engines` row", row and row.group(0))):
        if not text:
            errors.append(f"docs/bench-format.md: {label} is missing")
            continue
        missing = [e for e in engines if f"`{e}`" not in text]
        if missing:
            errors.append(f"docs/bench-format.md: {label} does not name engine(s) {', '.join(missing)} "
                          "(a sweep's default is every engine of the registry)")

    # 2. Exit codes.
    top = subprocess.run([octocd, "--help"], capture_output=True, text=True, check=True).stdout
    m = re.search(r"Exit codes: (.*?)\nUsage:", top, re.S)
    codes = sorted(set(re.findall(r"\b(\d{1,3})\b", m.group(1)))) if m else []
    if not codes:
        errors.append("octocd --help: no 'Exit codes:' list")
    cli = page("docs/cli.md")
    table = cli.split("\n## Exit codes\n", 1)[-1].split("\n## ", 1)[0]
    rows = set()
    for line in table.splitlines():
        cell = re.match(r"^\| ([0-9, /]+) \|", line)
        if cell:
            rows.update(re.findall(r"\d+", cell.group(1)))
    readme = page("README.md")
    sentence = re.search(r"Exit codes: (.*?)(?:\.\s|\.$|\n\n)", readme, re.S)
    said = set(re.findall(r"\b(\d{1,3})\b", sentence.group(1))) if sentence else set()
    for c in codes:
        if c not in rows:
            errors.append(f"docs/cli.md: exit code {c} (octocd --help) is no row of its 'Exit codes' table")
        if c not in said:
            errors.append(f"README.md: exit code {c} (octocd --help) is not in its 'Exit codes:' sentence")

    # 3. The nightly's default scene set.
    nightly = page("scripts/nightly.sh")
    block = re.search(r"^default_set=\((.*?)\)", nightly, re.M | re.S)
    names = block.group(1).split() if block else []
    if not names:
        errors.append("scripts/nightly.sh: no default_set")
    for n in names:
        if not (root / "datasets/scenes" / f"{n}.json").exists():
            errors.append(f"scripts/nightly.sh: default_set names {n}, no datasets/scenes/{n}.json")
    for doc in ("docs/validation-output.md", "docs/cli.md"):
        found = re.findall(r"default scene set \((\d+) scenes", page(doc))
        if not found:
            errors.append(f"{doc}: does not give the nightly's default scene set's size "
                          f"('default scene set ({len(names)} scenes')")
        for k in found:
            if int(k) != len(names):
                errors.append(f"{doc}: the default scene set has {k} scenes; scripts/nightly.sh's has {len(names)}")
    expect = json.loads(page("scripts/nightly-expect.json"))["expectations"]
    conservation = {e["scene"] for e in expect if "scene" in e and e["row"] == "conservation"}
    fails = re.search(r"conservation` row fails on (\d+) of the (\d+) scenes", page("docs/validation.md"))
    if not fails:
        errors.append("docs/validation.md: no 'conservation` row fails on K of the N scenes'")
    elif (int(fails.group(1)), int(fails.group(2))) != (len(conservation), len(names)):
        errors.append(f"docs/validation.md: conservation fails on {fails.group(1)} of {fails.group(2)} scenes; "
                      f"scripts/nightly-expect.json records {len(conservation)} of the {len(names)} of default_set")

    # 4. Tolerances.
    defs = re.findall(r'OCTOCD_TOLERANCE\((\w+),\s*([^,]+?),\s*"([^"]*)"',
                      page("validation/include/octocd/tolerances.def"))
    tol = page("docs/validation.md").split("\n| name | default | unit |\n", 1)
    if len(tol) < 2:
        errors.append("docs/validation.md: no tolerances table ('| name | default | unit |')")
    table = tol[-1].split("\n\n", 1)[0] if len(tol) == 2 else ""
    rows = re.findall(r"^\| `(\w+)` \| ([^|]+?) \| ([^|]+?) \|$", table, re.M)
    if len(defs) < 10:
        errors.append(f"tolerances.def: {len(defs)} entries read: too few to check")
    if rows != defs:
        extra = [r for r in rows if r not in defs]
        missing = [d for d in defs if d not in rows]
        errors.append(f"docs/validation.md: its tolerances table differs from tolerances.def: missing or different "
                      f"{missing}, not in tolerances.def {extra}" + ("" if missing or extra else ", the order"))

    if errors:
        print("FAIL:\n" + "\n".join(errors))
        return 1
    print(f"docs agree with the code: {len(engines)} engines, exit codes {', '.join(codes)}, the nightly's "
          f"{len(names)} default scenes ({len(conservation)} with conservation expected), {len(defs)} tolerances")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
