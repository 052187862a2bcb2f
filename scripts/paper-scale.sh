#!/usr/bin/env bash
# Trains ASP N = 2 at the paper's scale (configs/paper/phi-comparison/asp.json --scale paper:
# 3.8 hours of this 2-core machine; `--device cuda` trains on a GPU), resumably: run it again
# after an interruption and `lfnet train --resume OUT` skips the stages whose model exists and
# continues the interrupted one from its last.ckpt. The final model becomes
# out/cache/asp-n2-paper.ckpt and its training log out/cache/asp-n2-paper.training.jsonl; then
# `scripts/results.sh paper-scale-asp-n2`.
# Usage: scripts/paper-scale.sh [extra lfnet train arguments, e.g. --device cuda]
# Pass lfnet's global options in LFNET_OPTS, e.g. LFNET_OPTS="--threads 1" beside other work;
# CONFIG, SCALE, OUT and MODEL change what is trained, at which scale, where, and the copy.
# SNAPSHOT names a folder of the repository that carries the run between machines
# (scripts/run-snapshot.sh): when OUT does not exist but SNAPSHOT does, the run continues from
# it; `scripts/run-snapshot.sh save OUT SNAPSHOT` refreshes it before a session ends.
set -euo pipefail
cd "$(dirname "$0")/.."
lfnet=${LFNET:-build/apps/lfnet}
config=${CONFIG:-configs/paper/phi-comparison/asp.json}
scale=${SCALE:-paper}
out=${OUT:-out/paper-scale/asp-n2}
model=${MODEL:-out/cache/asp-n2-paper.ckpt}
snapshot=${SNAPSHOT:-}
if [[ -n $snapshot && ! -e $out && -f $snapshot/config.json ]]; then
  scripts/run-snapshot.sh restore "$snapshot" "$out"
fi
if [[ -f $out/config.json ]]; then
  echo "== resuming $out"
  # shellcheck disable=SC2086
  "$lfnet" ${LFNET_OPTS:-} train --resume "$out" "$@"
else
  # shellcheck disable=SC2086
  "$lfnet" ${LFNET_OPTS:-} train "$config" --scale "$scale" --out "$out" "$@"
fi
mkdir -p "$(dirname "$model")"
cp "$(ls -t "$out"/models/*.ckpt | head -n1)" "$model.tmp" && mv "$model.tmp" "$model"
cp "$out/training.jsonl" "${model%.ckpt}.training.jsonl"
ls -l "$model"
