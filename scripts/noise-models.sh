#!/usr/bin/env bash
# The noise models of lfnet's architecture (docs/architectures.md, "Noise"), each finetuned
# from models/lfnet-asp-n2.ckpt for the same number of steps (configs/models/lfnet-asp-n2.json
# at the paper scale, 8 epochs, lr 3e-4):
#   noise-aware  configs/models/lfnet-asp-n2-noise.json: sigma uniform in [0, 0.25], each
#                crop weighted by s / (s + sigma) (loss.noise_scale)  -> models/lfnet-asp-n2-noise.ckpt
#   sigma-0.1    one noise level alone                               -> models/lfnet-noise/sigma-0.1.ckpt
#   sigma-0.2                                                         -> models/lfnet-noise/sigma-0.2.ckpt
# Resumable: a model that exists is skipped, an interrupted run continues from its folder.
# Then `scripts/results.sh noise-sweep report`. Usage: scripts/noise-models.sh [NAME...];
# LFNET_THREADS (default 1: it runs beside other work) sets --threads.
set -euo pipefail
cd "$(dirname "$0")/.."
lfnet=${LFNET:-build/apps/lfnet}
threads=${LFNET_THREADS:-1}
init=models/lfnet-asp-n2.ckpt
finetune=(--scale paper --init "$init" --set training.epochs=8 --set training.lr=0.0003)

declare -A models=(
  [noise-aware]=models/lfnet-asp-n2-noise.ckpt
  [sigma-0.1]=models/lfnet-noise/sigma-0.1.ckpt
  [sigma-0.2]=models/lfnet-noise/sigma-0.2.ckpt
)
order=(noise-aware sigma-0.1 sigma-0.2)
names=("$@")
[[ ${#names[@]} -eq 0 ]] && names=("${order[@]}")
for name in "${names[@]}"; do
  [[ -n ${models[$name]+x} ]] || { echo "unknown model '$name' (known: ${order[*]})" >&2; exit 2; }
  model=${models[$name]}
  out=out/noise/lfnet-$name
  if [[ -f $model ]]; then
    echo "== $name: $model exists, skipped"
    continue
  fi
  echo "== $name: training ($(date -u +%H:%M))"
  if [[ -f $out/config.json ]]; then
    "$lfnet" --threads "$threads" train --resume "$out"
  elif [[ $name == noise-aware ]]; then
    "$lfnet" --threads "$threads" train configs/models/lfnet-asp-n2-noise.json "${finetune[@]}" \
      --out "$out"
  else
    "$lfnet" --threads "$threads" train configs/models/lfnet-asp-n2.json "${finetune[@]}" \
      --set "dataset.noise_range=[${name#sigma-},${name#sigma-}]" --out "$out"
  fi
  mkdir -p "$(dirname "$model")"
  cp "$(ls -t "$out"/models/*.ckpt | head -n1)" "$model.tmp"
  mv "$model.tmp" "$model"
  cp "$out/training.jsonl" "${model%.ckpt}.training.jsonl"
  echo "== $name: done ($(date -u +%H:%M))"
done
