#!/usr/bin/env bash
# Installs what is missing, builds, and runs the main job on built-in data: the quickstart
# experiment trains a reconstruction network on procedural scenes (no data needed), then
# evaluates it against the baselines on a held-out scene, and writes its report with training
# curves and the accuracy-against-time plot. Usage: scripts/run.sh [OUT_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
LFNET_TARGET=lfnet scripts/build.sh  # the program only; scripts/test.sh builds the tests
out=${1:-out/quickstart}
build/apps/lfnet experiment configs/quickstart.json --out "$out" --force
build/apps/lfnet report "$out"
echo
echo "run.sh: results in $out/results.jsonl, the report in $out/report.md; the model is $out/models/cnn.ckpt"
/usr/bin/python3 - "$out/results.jsonl" <<'PY' || true
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
print(f"{'method':<12} {'light field':<16} {'mode':<9} {'stride':>6} {'PSNR dB':>8} {'SSIM':>7} {'seconds':>8}")
for r in rows:
    print(f"{r['method']:<12} {r['light_field']:<16} {r['mode']:<9} {r['stride']:>6} "
          f"{r['psnr_db']:>8.2f} {r['ssim']:>7.4f} {r['seconds']:>8.2f}")
PY
