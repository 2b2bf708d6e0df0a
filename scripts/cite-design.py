#!/usr/bin/env python3
"""Rewrite citations of the external specification into citations of docs/design.md.

    scripts/cite-design.py ROOT [--dry-run] [--show N]

Walks the text files of the repository at ROOT (its tracked files when ROOT is a git work
tree, else every file under it) and rewrites, in place:

    SPEC 13b.12               -> design.md section 13b.12
    (SPEC 6)                  -> (design.md section 6)
    SPEC 5.1-5.3              -> design.md sections 5.1-5.3
    SPEC 13 / 13b, SPEC 4.1 and 6, SPEC 13b.7, 13b.8
                              -> design.md sections 13 / 13b, ...
    SPEC section 8            -> design.md section 8
    SPEC 6 revision 2, revision 2 of SPEC 6
                              -> design.md section 6 (design.md has no revisions)
    SPEC<newline># 14b        -> design.md section<newline># 14b (a comment wrapped mid-citation)
    the SPEC text / the SPEC's / the SPEC
                              -> the text of docs/design.md / docs/design.md's / docs/design.md
    `../shared/SPEC.md`       -> docs/design.md; a Markdown link in Markdown files:
                                 [docs/design.md](docs/design.md) in README.md,
                                 [design.md](design.md) under docs/, a relative link elsewhere
    `../shared/paper.md`      -> the paper's bibliographic reference (Mathematics 2025, 13, 3230)

Only the upper-case word SPEC followed by a section number (or the phrases above) is a
citation: identifiers and strings such as `spec6`, `response_model = "spec6"`, `Spec` are
left alone. A comment ruler that a rewrite lengthens (`# ---- gpu (SPEC 11) -------`) loses
as many dashes as it gained. Skipped: .git, build*/, datasets/cache/, reports/**.csv,
fuzz/regressions/, docs/design.md and this script. Prints the number of rewrites per file,
the total, lines that a rewrite pushed past 120 columns, and every SPEC or ../shared
occurrence left (with its line), so nothing is lost silently. Standard library only.
"""

import argparse
import os
import re
import subprocess
import sys

PAPER_TITLE = ("Toward Real-Time Scalable Rigid-Body Simulation Using GPU-Optimized Collision "
               "Detection and Response")
PAPER_REF_MD = "*Mathematics* 2025, 13, 3230"
PAPER_REF_TEXT = "Mathematics 2025, 13, 3230"

TEXT_SUFFIXES = (".cpp", ".hpp", ".h", ".hh", ".cc", ".c", ".cu", ".cuh", ".py", ".pyi",
                 ".cmake", ".in", ".sh", ".bash", ".md", ".json", ".txt", ".toml", ".yml",
                 ".yaml", ".cfg", ".ini")
TEXT_NAMES = ("CMakeLists.txt", "CMakePresets.json", "Makefile", "Dockerfile")
SELF = os.path.join("scripts", "cite-design.py")
DESIGN = os.path.join("docs", "design.md")

# One section reference: 6, 13b, 5.1, 13b.12, and a range of them: 5.1-5.3, 4.1–4.2.
REF = r"\d+[a-z]?(?:\.\d+)?(?:[-\u2013]\d+[a-z]?(?:\.\d+)?)?"
# A list of references after one SPEC: "13b.13, 14b", "4.1 then 4.2", "7 and 13", "13 / 13b".
LIST = REF + r"(?:(?:,\s?|\s/\s?|/|\s(?:and|then|or)\s)" + REF + r")*"
# The blank between SPEC and its number; a comment may wrap there ("(SPEC\n# 14b)").
GAP = r"(?:[ \t]+|[ \t]*\n[ \t]*(?:///?|#|\*|--)?[ \t]*)"
# Optional history around a citation, dropped: "revision 2 of SPEC 6", "SPEC 6 revision 2".
REV_BEFORE = r"(?:\brevision\s+\d+\s+of\s+)?"
REV_AFTER = r"(?:\s+revision\s+\d+\b)?"

CITATION = re.compile(REV_BEFORE + r"\bSPEC(?P<gap>" + GAP + r")(?:section(?P<gap2>" + GAP +
                      r"))?(?P<refs>" + LIST + r")(?![\w.]*\d)" + REV_AFTER)
PHRASES = [
    (re.compile(r"\bthe SPEC text\b"), "the text of {design}"),
    (re.compile(r"\bthe SPEC's\b"), "{design}'s"),
    (re.compile(r"\bthe SPEC\b"), "{design}"),
]
SPEC_PATH = re.compile(r"`?(?:\.\./)+shared/SPEC\.md`?")
PAPER_PATH = re.compile(r"`?(?:\.\./)+shared/paper\.md`?")
# README's form: "after *Mathematics* 2025, 13, 3230 (`../shared/paper.md`)".
PAPER_BY_REF = re.compile(r"\*Mathematics\*\s+2025,\s+13,\s+3230\s*\(`?(?:\.\./)+shared/paper\.md`?\)")
RULER = re.compile(r"(?P<body>.*?)(?P<dashes>[ ]-{4,}|[ ]={4,})$")
LEFT = re.compile(r"\bSPEC\b|\.\./shared")


def is_text_path(rel):
    name = os.path.basename(rel)
    return name in TEXT_NAMES or rel.endswith(TEXT_SUFFIXES)


def skipped(rel):
    parts = rel.split(os.sep)
    if parts[0] == ".git" or parts[0].startswith("build"):
        return True
    if rel.startswith(os.path.join("datasets", "cache") + os.sep):
        return True
    if rel.startswith(os.path.join("fuzz", "regressions") + os.sep):
        return True
    if parts[0] == "reports" and rel.endswith(".csv"):
        return True
    return rel in (SELF, DESIGN)


def list_files(root):
    """Tracked files of a git work tree, else every file below root (relative paths)."""
    if os.path.exists(os.path.join(root, ".git")):  # a repository or a worktree
        try:
            out = subprocess.run(["git", "-C", root, "ls-files", "-z"], check=True,
                                 capture_output=True).stdout.decode()
            return sorted(os.path.normpath(f) for f in out.split("\0") if f)
        except (OSError, subprocess.CalledProcessError):
            pass
    files = []
    for d, dirs, names in os.walk(root):
        rel_d = os.path.relpath(d, root)
        dirs[:] = sorted(x for x in dirs
                         if not skipped(os.path.normpath(os.path.join(rel_d, x, "x"))))
        for n in names:
            files.append(os.path.normpath(os.path.join(rel_d, n)))
    return sorted(files)


def has_shebang(path):
    try:
        with open(path, "rb") as f:
            return f.read(2) == b"#!"
    except OSError:
        return False


class Rewriter:
    """The rewrites of one file; `count` is the number of citations rewritten."""

    def __init__(self, rel):
        self.rel = rel
        self.count = 0
        self.markdown = rel.endswith(".md")
        if self.markdown:
            link = os.path.relpath(DESIGN, os.path.dirname(rel) or ".").replace(os.sep, "/")
            label = "design.md" if os.path.dirname(rel) == "docs" else "docs/design.md"
            self.design_path = "[{}]({})".format(label, link)
        else:
            self.design_path = "docs/design.md"
        # Words used in running text ("the SPEC text" -> "the text of docs/design.md").
        self.design_word = "docs/design.md"

    def _citation(self, m):
        self.count += 1
        refs = m.group("refs")
        plural = bool(re.search(r"[-\u2013,/]|\s(?:and|then|or)\s", refs))
        gap = m.group("gap2") if m.group("gap2") is not None else m.group("gap")
        # "SPEC<gap>section<gap2>N": keep the blank before the number (it may hold a newline).
        if m.group("gap2") is None and "\n" not in gap:
            gap = " "
        return "design.md " + ("sections" if plural else "section") + gap + refs

    def _sub(self, pattern, repl, text):
        new, n = pattern.subn(repl, text)
        self.count += n
        return new

    def line_or_text(self, text):
        # The title is wrapped after "GPU-Optimized" to keep Markdown prose lines short.
        title = PAPER_TITLE.replace("GPU-Optimized ", "GPU-Optimized\n") if self.markdown \
            else PAPER_TITLE
        text = self._sub(PAPER_BY_REF, lambda m: "the paper *{}* ({})".format(title, PAPER_REF_MD),
                         text)
        text = self._sub(PAPER_PATH, lambda m: "the paper ({})".format(
            PAPER_REF_MD if self.markdown else PAPER_REF_TEXT), text)
        text = self._sub(SPEC_PATH, lambda m: self.design_path, text)
        text = CITATION.sub(self._citation, text)
        for pattern, repl in PHRASES:
            text = self._sub(pattern, lambda m, r=repl: r.format(design=self.design_word), text)
        return text

    def rewrite(self, text):
        lines = text.split("\n")
        # Comment rulers first, one line at a time, so that their dashes can shrink.
        for i, line in enumerate(lines):
            m = RULER.match(line)
            if not m or "SPEC" not in m.group("body"):
                continue
            body = self.line_or_text(m.group("body"))
            dashes = m.group("dashes")
            grown = len(body) - len(m.group("body"))
            keep = max(len(dashes) - 1 - grown, 3)
            lines[i] = body + " " + dashes[1] * keep
        return self.line_or_text("\n".join(lines))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("root", help="repository root")
    ap.add_argument("--dry-run", action="store_true", help="count and report, write nothing")
    ap.add_argument("--show", type=int, default=0, metavar="N",
                    help="print the first N rewritten lines (old and new)")
    args = ap.parse_args()
    root = os.path.abspath(args.root)
    if not os.path.isdir(root):
        sys.exit("cite-design: {}: not a directory".format(args.root))

    total, files_changed, shown, long_lines, leftovers = 0, 0, 0, [], []
    for rel in list_files(root):
        if skipped(rel):
            continue
        path = os.path.join(root, rel)
        if not os.path.isfile(path) or os.path.islink(path):
            continue
        if not (is_text_path(rel) or has_shebang(path)):
            continue
        try:
            with open(path, encoding="utf-8", newline="") as f:
                text = f.read()
        except (UnicodeDecodeError, OSError):
            continue
        if "SPEC" not in text and "shared/" not in text:
            continue
        rw = Rewriter(rel)
        new = rw.rewrite(text)
        old_lines, new_lines = text.split("\n"), new.split("\n")
        for no, line in enumerate(new_lines, 1):
            if LEFT.search(line):
                leftovers.append("{}:{}: {}".format(rel, no, line.strip()))
        if new == text:
            continue
        files_changed += 1
        total += rw.count
        print("{:6d}  {}".format(rw.count, rel))
        if len(old_lines) == len(new_lines):
            for no, (a, b) in enumerate(zip(old_lines, new_lines), 1):
                if a == b:
                    continue
                if len(b) > 120 >= len(a) and not rel.endswith(".md"):
                    long_lines.append("{}:{}: {} columns".format(rel, no, len(b)))
                if shown < args.show:
                    shown += 1
                    print("        {}:{}\n          - {}\n          + {}".format(rel, no, a.strip(),
                                                                             b.strip()))
        if not args.dry_run:
            with open(path, "w", encoding="utf-8", newline="") as f:
                f.write(new)
    print("{:6d}  rewrites in {} files{}".format(total, files_changed,
                                                " (dry run: nothing written)" if args.dry_run
                                                else ""))
    if long_lines:
        print("lines a rewrite pushed past 120 columns ({}):".format(len(long_lines)))
        for x in long_lines:
            print("  " + x)
    if leftovers:
        print("left as they are ({}): SPEC or ../shared that is no section citation:".format(
            len(leftovers)))
        for x in leftovers:
            print("  " + x)
    return 0


if __name__ == "__main__":
    sys.exit(main())
