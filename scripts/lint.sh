#!/usr/bin/env bash
# Format and lint: clang-format on every C++ file (any difference fails), clang-tidy
# (.clang-tidy) on the C++ sources changed since LINT_BASE (default: the previous commit).
# Usage: scripts/lint.sh [--fix]   (--fix rewrites the files clang-format would change)
# Needs a configured build/ (its compile_commands.json); scripts/test.sh runs it after building.
set -euo pipefail
cd "$(dirname "$0")/.."
mapfile -t files < <(git ls-files '*.cc' '*.h' | grep -v '^tests/fuzz/corpus/')
if [[ ${1:-} == --fix ]]; then
  clang-format -i "${files[@]}"
  echo "lint: formatted ${#files[@]} files"
  exit 0
fi
if ! clang-format --dry-run -Werror "${files[@]}" 2>/tmp/lfnet-format.$$; then
  head -n 40 /tmp/lfnet-format.$$
  echo "lint: $(grep -c 'error:' /tmp/lfnet-format.$$) formatting differences; run scripts/lint.sh --fix"
  rm -f /tmp/lfnet-format.$$
  exit 1
fi
rm -f /tmp/lfnet-format.$$
echo "lint: clang-format: ${#files[@]} files clean"

base=${LINT_BASE:-HEAD~1}
if ! git rev-parse -q --verify "$base^{commit}" >/dev/null; then
  echo "lint: clang-tidy: no $base to compare with; skipped"
  exit 0
fi
mapfile -t changed < <(git diff --name-only --diff-filter=d "$base" -- '*.cc' | grep -v '^tests/fuzz/' || true)
if [[ ${#changed[@]} -eq 0 ]]; then
  echo "lint: clang-tidy: no C++ source changed since $base"
  exit 0
fi
# The build's precompiled headers are GCC's: clang-tidy reads the same commands without them.
# A unity build compiles generated files that include the sources; each source gets its
# batch's command, so clang-tidy finds every one of them.
db=$(mktemp -d)
trap 'rm -rf "$db"' EXIT
/usr/bin/python3 - build/compile_commands.json "$db/compile_commands.json" <<'PY'
import json, os, re, shlex, sys
out = []
commands = []
for c in json.load(open(sys.argv[1])):
    if "/Unity/unity_" not in c["file"]:
        commands.append(c)
        continue
    unity = os.path.join(c["directory"], c["file"])
    for source in re.findall(r'^#include "([^"]+)"', open(unity).read(), re.M):
        entry = dict(c, file=source)
        if "command" in c:
            entry["command"] = c["command"].replace(c["file"], source)
        else:
            entry["arguments"] = [source if a == c["file"] else a for a in c["arguments"]]
        commands.append(entry)
for c in commands:
    args = shlex.split(c["command"]) if "command" in c else c["arguments"]
    kept, skip = [], False
    for a in args:
        if skip:
            skip = False
            continue
        if a == "-include" :
            skip = True
            continue
        if a.startswith("-Winvalid-pch"):
            continue
        kept.append(a)
    out.append({"directory": c["directory"], "file": c["file"], "arguments": kept})
json.dump(out, open(sys.argv[2], "w"))
PY
warnings=0
for f in "${changed[@]}"; do
  # Printed to stderr through the descriptor: `tee /dev/stderr` would reopen a log file that
  # stderr is redirected to, and truncate it.
  out=$(clang-tidy -p "$db" --quiet "$f" 2>/dev/null || true)
  [[ -n $out ]] && printf '%s\n' "$out" >&2
  n=$(grep -c ': warning:' <<< "$out" || true)
  warnings=$((warnings + n))
done
echo "lint: clang-tidy: ${#changed[@]} changed source(s) since $base, $warnings warning(s)"
[[ $warnings -eq 0 ]]
