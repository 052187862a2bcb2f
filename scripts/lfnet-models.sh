#!/usr/bin/env bash
# The shipped models of lfnet's architecture (docs/models.md), each a finetuning of
# models/lfnet-asp-n2-first20.ckpt (the paper scale of configs/models/lfnet-asp-n2.json, 20
# epochs; `lfnet train --init`) at the paper scale of its config:
#   lfnet-asp-n2   configs/models/lfnet-asp-n2.json   -> models/lfnet-asp-n2.ckpt: 30 more epochs
#                  at lr 4e-4 on new random scenes and crops (seeds 9000 and 11)
#   lfnet-asp-n15  configs/models/lfnet-asp-n15.json  -> models/lfnet-asp-n15.ckpt: across Phi
#   lfnet-mask-n2  configs/models/lfnet-mask-n2.json  -> models/lfnet-mask-n2.ckpt  (10 epochs at
#                  lr 5e-4; the U-Net reads the per-pixel pseudo-inverse, so its weights fit
#                  every Phi of the same view grid)
# models/lfnet-asp-n2-first20.ckpt itself: `CONFIG=configs/models/lfnet-asp-n2.json
# MODEL=models/lfnet-asp-n2-first20.ckpt scripts/paper-scale.sh` (20 epochs of 8,000 crops).
# Resumable: a model that exists is skipped, an interrupted run continues from its folder
# (out/lfnet-models/NAME). Then `scripts/results.sh other-phi report`.
# Usage: scripts/lfnet-models.sh [NAME...]; LFNET_THREADS (default 1: it runs beside other
# work) sets --threads.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/model-steps.sh
lfnet=${LFNET:-build/apps/lfnet}
threads=${LFNET_THREADS:-1}
init=models/lfnet-asp-n2-first20.ckpt
order=(lfnet-asp-n2 lfnet-asp-n15 lfnet-mask-n2)
declare -A finetune=(
  [lfnet-asp-n2]="--set training.epochs=30 --set training.lr=0.0004 --set data.random_seed=9000
                  --set dataset.seed=11"
  [lfnet-asp-n15]="--set training.epochs=10 --set training.lr=0.0005"
  [lfnet-mask-n2]="--set training.epochs=10 --set training.lr=0.0005"
)
names=("$@")
[[ ${#names[@]} -eq 0 ]] && names=("${order[@]}")
for name in "${names[@]}"; do
  config=configs/models/$name.json
  [[ -f $config ]] || { echo "unknown model '$name' (known: ${order[*]})" >&2; exit 2; }
  model=models/$name.ckpt
  out=out/lfnet-models/$name
  model_exists "$name" "$model" && continue
  if [[ -f $out/config.json ]]; then
    "$lfnet" --threads "$threads" train --resume "$out"
  else
    # shellcheck disable=SC2086
    "$lfnet" --threads "$threads" train "$config" --scale paper --init "$init" \
      ${finetune[$name]} --out "$out"
  fi
  keep_model "$out" "$model"
  if [[ $name == lfnet-asp-n2 ]]; then  # its log holds all 50 epochs
    cat "${init%.ckpt}.training.jsonl" "$out/training.jsonl" > "${model%.ckpt}.training.jsonl"
  else
    cp "$out/training.jsonl" "${model%.ckpt}.training.jsonl"
  fi
  echo "== $name: done ($(date -u +%H:%M))"
done
