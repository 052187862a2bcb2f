#!/usr/bin/env bash
# Trains ASP N = 2 at the paper's scale (configs/paper/phi-comparison/asp.json --scale paper:
# 3.8 hours of this 2-core machine; `--device cuda` trains on a GPU), stage by stage
# and resumably: a stage whose model exists is skipped, an interrupted one continues from its
# last.ckpt. Run it again after an interruption. The final model becomes
# models/asp-n2-paper.ckpt and its training log models/asp-n2-paper.training.jsonl; then
# `scripts/results.sh paper-scale-asp-n2`.
# Usage: scripts/paper-scale.sh [extra lfnet train arguments, e.g. --device cuda]
# Pass lfnet's global options in LFNET_OPTS, e.g. LFNET_OPTS="--threads 1" beside other work;
# CONFIG, SCALE, OUT and MODEL change what is trained, at which scale, where, and the copy.
set -euo pipefail
cd "$(dirname "$0")/.."
lfnet=${LFNET:-build/apps/lfnet}
config=${CONFIG:-configs/paper/phi-comparison/asp.json}
scale=${SCALE:-paper}
out=${OUT:-out/paper-scale/asp-n2}
model=${MODEL:-models/asp-n2-paper.ckpt}
stages=$(/usr/bin/python3 -c 'import json,sys; print(" ".join(s if isinstance(s,str) else s["name"] for s in json.load(open(sys.argv[1]))["stages"]))' "$config")
last=
for stage in $stages; do
  last=$stage
  if [[ -f $out/models/$stage.ckpt ]]; then
    echo "== $stage: done ($out/models/$stage.ckpt)"
    continue
  fi
  if [[ -f $out/models/$stage/last.ckpt ]]; then
    echo "== $stage: resuming from $out/models/$stage/last.ckpt"
    # shellcheck disable=SC2086
    "$lfnet" ${LFNET_OPTS:-} train "$config" --scale "$scale" --out "$out" --stage "$stage" \
      --resume "$out/models/$stage/last.ckpt" "$@"
  else
    echo "== $stage: training"
    # shellcheck disable=SC2086
    "$lfnet" ${LFNET_OPTS:-} train "$config" --scale "$scale" --out "$out" --stage "$stage" --force "$@"
  fi
done
cp "$out/models/$last.ckpt" "$model.tmp"
mv "$model.tmp" "$model"
cp "$out/training.jsonl" "${model%.ckpt}.training.jsonl"
ls -l "$model"
