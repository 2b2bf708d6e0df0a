#!/usr/bin/env bash
# Regenerates the `--help` blocks of docs/cli.md from the built `octocd` (the test
# CliUser.CliDocMatchesHelp fails when they differ). Each block sits between
#   <!-- BEGIN octocd SUB --help -->  and  <!-- END octocd SUB --help -->
# and is replaced by the command's output in a ```text fence; the prose around the blocks
# is kept. A subcommand `octocd --help` lists but the page lacks gets a new section at the
# end (write its prose by hand).
# Usage: scripts/cli-doc.sh [BUILD_DIR]   (default: build; $OCTOCD_BIN wins)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bin="${OCTOCD_BIN:-${1:-build}/octocd}"
doc="$root/docs/cli.md"
[ -x "$bin" ] || { echo "cli-doc: no octocd at '$bin'" >&2; exit 2; }
subs=$("$bin" --help | sed -n '/^Subcommands:/,/^$/p' | sed -n 's/^  \([a-z][a-z-]*\) .*/\1/p')
for label in "octocd --help" $(for s in $subs; do echo "octocd_${s}_--help"; done); do
  label="${label//_/ }"
  if ! grep -qF "<!-- BEGIN $label -->" "$doc"; then
    printf '\n## `%s`\n\n<!-- BEGIN %s -->\n```text\n```\n<!-- END %s -->\n' "${label% --help}" "$label" "$label" >>"$doc"
  fi
  help="$(mktemp)"
  # shellcheck disable=SC2086
  "$bin" ${label#octocd } >"$help"  # the exact bytes, trailing blank lines included
  /usr/bin/env python3 - "$doc" "$label" "$help" <<'PY'
import sys
path, label, help_path = sys.argv[1], sys.argv[2], sys.argv[3]
doc = open(path).read()
help_text = open(help_path).read()
begin = f"<!-- BEGIN {label} -->\n"
end = f"<!-- END {label} -->"
b = doc.index(begin) + len(begin)
e = doc.index(end, b)
doc = doc[:b] + "```text\n" + help_text + "```\n" + doc[e:]
open(path, "w").write(doc)
PY
  rm -f "$help"
done
echo "cli-doc: $doc updated"
