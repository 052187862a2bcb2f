#!/usr/bin/env bash
# The shipped models of lfnet's architecture for other cameras (docs/models.md), each finetuned
# across Phi from models/lfnet-asp-n2.ckpt (`lfnet train --init`: the U-Net reads the per-pixel
# pseudo-inverse, so its weights fit every Phi of the same view grid), at the paper scale of its
# config for 10 epochs at lr 5e-4:
#   lfnet-asp-n15  configs/models/lfnet-asp-n15.json  -> models/lfnet-asp-n15.ckpt
#   lfnet-mask-n2  configs/models/lfnet-mask-n2.json  -> models/lfnet-mask-n2.ckpt
# Resumable: a model that exists is skipped, an interrupted run continues from its folder
# (out/lfnet-models/NAME). Then `scripts/results.sh other-phi report`.
# Usage: scripts/lfnet-models.sh [NAME...]; LFNET_THREADS (default 1: it runs beside other
# work) sets --threads.
set -euo pipefail
cd "$(dirname "$0")/.."
lfnet=${LFNET:-build/apps/lfnet}
threads=${LFNET_THREADS:-1}
init=models/lfnet-asp-n2.ckpt
order=(lfnet-asp-n15 lfnet-mask-n2)
names=("$@")
[[ ${#names[@]} -eq 0 ]] && names=("${order[@]}")
for name in "${names[@]}"; do
  config=configs/models/$name.json
  [[ -f $config ]] || { echo "unknown model '$name' (known: ${order[*]})" >&2; exit 2; }
  model=models/$name.ckpt
  out=out/lfnet-models/$name
  if [[ -f $model ]]; then
    echo "== $name: $model exists, skipped"
    continue
  fi
  echo "== $name: training ($(date -u +%H:%M))"
  if [[ -f $out/config.json ]]; then
    "$lfnet" --threads "$threads" train --resume "$out"
  else
    "$lfnet" --threads "$threads" train "$config" --scale paper --init "$init" \
      --set training.epochs=10 --set training.lr=0.0005 --out "$out"
  fi
  cp "$(ls -t "$out"/models/*.ckpt | head -n1)" "$model.tmp"
  mv "$model.tmp" "$model"
  cp "$out/training.jsonl" "${model%.ckpt}.training.jsonl"
  echo "== $name: done ($(date -u +%H:%M))"
done
