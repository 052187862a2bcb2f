#!/bin/bash
# What a command costs end to end against its reconstruction alone, on a random procedural scene
# of 593 x 840 x 5 x 5 (colour, 8-bit views; render --random 7, made once by the first binary)
# with models/lfnet-asp-n2.ckpt, two threads: for each lfnet binary given (default
# build/apps/lfnet), alternating, RUNS times (default 3), one line per command
#   BINARY  COMMAND  reconstruction-seconds  end-to-end-seconds  ratio
# for `reconstruct --out` (from its reconstruction.json) and `evaluate --json` (docs/performance.md,
# "End to end").
# With ALL=1 it also times, by the wall clock around each process, `evaluate --json --out`,
# `reconstruct --method pinv --out` and `info --lf` (the commands a new user runs first), one line
#   BINARY  COMMAND  seconds-lfnet-reports  wall-seconds
# each ("info" reports the seconds it took to load the light field).
# Usage: scripts/end-to-end.sh [BINARY...]   (RUNS=5 scripts/end-to-end.sh ...; ALL=1 ...)
set -euo pipefail
cd "$(dirname "$0")/.."
model=models/lfnet-asp-n2.ckpt
[[ $# -gt 0 ]] || set -- build/apps/lfnet
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
data=$work/scene
"$1" --threads 2 --log-level off render --random 7 --size 593x840 --bits 8 --out "$data"
"$1" --threads 2 --log-level off simulate --lf "$data" --phi "$model" --out "$work/acq"
line() {
  /usr/bin/python3 - "$1" "$2" "$3" <<'PY'
import json, sys
r = json.load(open(sys.argv[3]))
e = r.get("end_to_end_seconds", float("nan"))
print("%s\t%s\t%.2f\t%.2f\t%.2f" % (sys.argv[1], sys.argv[2], r["seconds"], e, e / r["seconds"]))
PY
}
# wall BINARY LABEL RECORD ARGS...: runs BINARY ARGS on two threads, prints the seconds the
# record (or, without one, info's "loaded in") reports and the wall seconds of the process.
wall() {
  local bin=$1 label=$2 record=$3
  shift 3
  local start end
  start=$(date +%s.%N)
  "$bin" --threads 2 --log-level off "$@" > "$work/stdout" 2>&1
  end=$(date +%s.%N)
  /usr/bin/python3 - "$bin" "$label" "$record" "$work/stdout" "$start" "$end" <<'PY'
import json, re, sys
bin_, label, record, stdout, start, end = sys.argv[1:]
if record:
    reported = json.load(open(record))["seconds"]
else:
    reported = float(re.search(r"loaded in:\s*([0-9.]+) s", open(stdout).read()).group(1))
print("%s\t%s\t%.2f\t%.2f" % (bin_, label, reported, float(end) - float(start)))
PY
}
for ((run = 1; run <= ${RUNS:-3}; run++)); do
  for bin in "$@"; do
    "$bin" --threads 2 --log-level off reconstruct --model "$model" --sensor "$work/acq" \
      --out "$work/rec" --force
    line "$bin" "reconstruct --out" "$work/rec/reconstruction.json"
    "$bin" --threads 2 --log-level off evaluate --model "$model" --lf "$data" \
      --json "$work/eval.json" --force > /dev/null
    line "$bin" "evaluate --json" "$work/eval.json"
    [[ -n ${ALL:-} ]] || continue
    wall "$bin" "evaluate --json --out" "$work/eval-out.json" evaluate --model "$model" \
      --lf "$data" --json "$work/eval-out.json" --out "$work/eval-out" --force
    wall "$bin" "reconstruct --method pinv --out" "$work/pinv/reconstruction.json" reconstruct \
      --method pinv --sensor "$work/acq" --out "$work/pinv" --force
    wall "$bin" "info --lf" "" info --lf "$data"
  done
done
