#!/usr/bin/env bash
# The noise models of lfnet's architecture (docs/architectures.md, "Noise"), finetuned from
# models/lfnet-asp-n2-first20.ckpt (configs/models/lfnet-asp-n2.json at the paper scale, 20
# epochs; docs/models.md), 8 epochs of
# 8,000 crops, lr 3e-4, for each model below but the last):
#   aware-s0.025  configs/models/lfnet-asp-n2-noise.json: sigma uniform in [0, 0.25], each
#                 crop weighted by s / (s + sigma) with s = 0.025 (loss.noise_scale)
#                                                   -> models/lfnet-noise/aware-s0.025.ckpt
#   sigma-0.1     one noise level alone             -> models/lfnet-noise/sigma-0.1.ckpt
#   sigma-0.2                                       -> models/lfnet-noise/sigma-0.2.ckpt
#   aware-s0.1    aware-s0.025 finetuned 8 more epochs (lr 2e-4) with the gentler weight
#                 s = 0.1 (a crop at sigma 0.2 weighs 1/3 of a noiseless one, not 1/9)
#                                                   -> models/lfnet-noise/aware-s0.1.ckpt
#   noise-aware   aware-s0.1 finetuned 8 more epochs (lr 2e-4, new crops: dataset.seed 21) with
#                 s = 0.2 and a third of the crops under shot and read noise instead
#                 (dataset.shot_read_fraction 0.3): the shipped noise-aware model
#                                                   -> models/lfnet-asp-n2-noise.ckpt
#                 (its training log holds the three finetunings, one after the other)
# Resumable: a model that exists is skipped, an interrupted run continues from its folder.
# Then `scripts/results.sh noise-sweep report`. Usage: scripts/noise-models.sh [NAME...];
# LFNET_THREADS (default 1: it runs beside other work) sets --threads.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/model-steps.sh
lfnet=${LFNET:-build/apps/lfnet}
threads=${LFNET_THREADS:-1}
# The first 20 epochs of lfnet-asp-n2 (docs/models.md), which these models were finetuned from.
init=models/lfnet-asp-n2-first20.ckpt
finetune=(--scale paper --init "$init" --set training.epochs=8 --set training.lr=0.0003)

declare -A models=(
  [aware-s0.025]=models/lfnet-noise/aware-s0.025.ckpt
  [sigma-0.1]=models/lfnet-noise/sigma-0.1.ckpt
  [sigma-0.2]=models/lfnet-noise/sigma-0.2.ckpt
  [aware-s0.1]=models/lfnet-noise/aware-s0.1.ckpt
  [noise-aware]=models/lfnet-asp-n2-noise.ckpt
)
order=(aware-s0.025 sigma-0.1 sigma-0.2 aware-s0.1 noise-aware)
names=("$@")
[[ ${#names[@]} -eq 0 ]] && names=("${order[@]}")
for name in "${names[@]}"; do
  [[ -n ${models[$name]+x} ]] || { echo "unknown model '$name' (known: ${order[*]})" >&2; exit 2; }
  model=${models[$name]}
  out=out/noise/lfnet-$name
  model_exists "$name" "$model" && continue
  if [[ -f $out/config.json ]]; then
    "$lfnet" --threads "$threads" train --resume "$out"
  elif [[ $name == aware-s0.1 ]]; then
    "$0" aware-s0.025
    "$lfnet" --threads "$threads" train configs/models/lfnet-asp-n2-noise.json --scale paper \
      --init models/lfnet-noise/aware-s0.025.ckpt --set training.epochs=8 \
      --set training.lr=0.0002 --set training.loss.noise_scale=0.1 --out "$out"
  elif [[ $name == noise-aware ]]; then
    "$0" aware-s0.1
    "$lfnet" --threads "$threads" train configs/models/lfnet-asp-n2-noise.json --scale paper \
      --init models/lfnet-noise/aware-s0.1.ckpt --set training.epochs=8 \
      --set training.lr=0.0002 --set training.loss.noise_scale=0.2 \
      --set dataset.shot_read_fraction=0.3 --set dataset.seed=21 --out "$out"
  elif [[ $name == aware-s0.025 ]]; then
    "$lfnet" --threads "$threads" train configs/models/lfnet-asp-n2-noise.json "${finetune[@]}" \
      --out "$out"
  else
    "$lfnet" --threads "$threads" train configs/models/lfnet-asp-n2.json "${finetune[@]}" \
      --set "dataset.noise_range=[${name#sigma-},${name#sigma-}]" --out "$out"
  fi
  keep_model "$out" "$model"
  if [[ $name == aware-s0.1 ]]; then
    # The second finetuning is named a stage of its own, so its curves follow the first's.
    { cat models/lfnet-noise/aware-s0.025.training.jsonl
      sed 's/"stage":"joint_scratch"/"stage":"joint_scratch, s = 0.1"/' "$out/training.jsonl"
    } > "${model%.ckpt}.training.jsonl"
  elif [[ $name == noise-aware ]]; then
    { cat models/lfnet-noise/aware-s0.1.training.jsonl
      sed 's/"stage":"joint_scratch"/"stage":"joint_scratch, s = 0.2, shot and read"/' \
        "$out/training.jsonl"
    } > "${model%.ckpt}.training.jsonl"
  else
    cp "$out/training.jsonl" "${model%.ckpt}.training.jsonl"
  fi
  echo "== $name: done ($(date -u +%H:%M))"
done
