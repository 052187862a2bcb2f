#!/bin/bash
# What `reconstruct --out` costs end to end against its reconstruction alone, on the paper's
# scene at aperture 5 (593 x 840 x 5 x 5) with models/lfnet-asp-n2.ckpt, two threads: for each
# lfnet binary given (default build/apps/lfnet), alternating, RUNS times (default 3), one line
#   BINARY  reconstruction-seconds  end-to-end-seconds  ratio
# from each run's reconstruction.json (docs/performance.md, "End to end").
# The paper's scene is the one #43 times commands on; this script reads only seconds, never a
# PSNR, so nothing is chosen by the scene's score.
# Usage: scripts/end-to-end.sh [BINARY...]   (RUNS=5 scripts/end-to-end.sh ...)
set -euo pipefail
cd "$(dirname "$0")/.."
data=../shared/data/mit_dragons_bunnies_5x5_ap5
model=models/lfnet-asp-n2.ckpt
[[ $# -gt 0 ]] || set -- build/apps/lfnet
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$1" --threads 2 --log-level off simulate --lf "$data" --phi "$model" --out "$work/acq"
for ((run = 1; run <= ${RUNS:-3}; run++)); do
  for bin in "$@"; do
    "$bin" --threads 2 --log-level off reconstruct --model "$model" --sensor "$work/acq" \
      --out "$work/rec" --force
    /usr/bin/python3 - "$bin" "$work/rec/reconstruction.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[2]))
e = r.get("end_to_end_seconds", float("nan"))
print("%s\t%.2f\t%.2f\t%.2f" % (sys.argv[1], r["seconds"], e, e / r["seconds"]))
PY
  done
done
