#!/usr/bin/env bash
# The shipped models of lfnet's architecture (docs/models.md). Each step finetunes a model
# (`lfnet train --init`) at the paper scale of its config: lfnet-asp-n2-c32, lfnet-asp-n15 and
# lfnet-mask-n2 start from models/lfnet-asp-n2-first20.ckpt (the paper scale of
# configs/models/lfnet-asp-n2.json, 20 epochs), lfnet-asp-n2-c48, lfnet-asp-n2-f10,
# lfnet-asp-n2-l3, lfnet-asp-n2-l4 and lfnet-asp-n2 from the step before them:
#   lfnet-asp-n2-c32  configs/models/lfnet-asp-n2.json -> models/lfnet-asp-n2-c32.ckpt: 30 more
#                     epochs at lr 4e-4 on new random scenes and crops (seeds 9000 and 11)
#   lfnet-asp-n2-c48  the same config -> models/lfnet-asp-n2-c48.ckpt: lfnet-asp-n2-c32 widened
#                     from 32 to 48 channels (train --init embeds the narrow U-Net in the wide
#                     one) and trained 14 more epochs at lr 3e-4 on new scenes and crops (15000, 15)
#   lfnet-asp-n2-f10  the same config -> models/lfnet-asp-n2-f10.ckpt: lfnet-asp-n2-c48 trained
#                     10 more epochs at lr 3e-4 on crops of 64 x 64 (4,500 per epoch) of new
#                     scenes, half of whose random scenes hold a man-made frame
#                     (frame_probability 0.5: docs/scenes.md; seeds 17000 and 17)
#   lfnet-asp-n2-l3   the same config -> models/lfnet-asp-n2-l3.ckpt: lfnet-asp-n2-f10 trained 14
#                     more epochs at lr 1e-4 on the same kind of crops of new scenes, 70 % of
#                     whose random scenes hold a frame (seeds 18000 and 18)
#   lfnet-asp-n2-l4   the same config -> models/lfnet-asp-n2-l4.ckpt: lfnet-asp-n2-l3 deepened to 4
#                     levels of 48, 96, 192 and 128 channels (train --init starts the new level
#                     as nothing) and trained 7 more epochs at lr 1e-4 on crops of 128 x 128
#                     (1,125 per epoch, half of every scene's rows for validation) of new scenes
#                     with frames in 70 % (seeds 21000 and 21)
#   lfnet-asp-n2      the same config -> models/lfnet-asp-n2.ckpt: lfnet-asp-n2-l4 distilled from
#                     its own self-ensemble (docs/training.md): 6 more epochs at lr 5e-5 on the
#                     same kind of crops of new scenes (seeds 24000 and 24), every crop's target
#                     the four-pass self-ensemble of lfnet-asp-n2-l4 in bfloat16
#   lfnet-asp-n15     configs/models/lfnet-asp-n15.json -> models/lfnet-asp-n15.ckpt: across Phi
#   lfnet-mask-n2     configs/models/lfnet-mask-n2.json -> models/lfnet-mask-n2.ckpt  (10 epochs
#                     at lr 5e-4; the U-Net reads the per-pixel pseudo-inverse, so its weights
#                     fit every Phi of the same view grid)
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
first20=models/lfnet-asp-n2-first20.ckpt
order=(lfnet-asp-n2-c32 lfnet-asp-n2-c48 lfnet-asp-n2-f10 lfnet-asp-n2-l3 lfnet-asp-n2-l4
       lfnet-asp-n2 lfnet-asp-n15 lfnet-mask-n2)
declare -A config=(
  [lfnet-asp-n2-c32]=configs/models/lfnet-asp-n2.json
  [lfnet-asp-n2-c48]=configs/models/lfnet-asp-n2.json
  [lfnet-asp-n2-f10]=configs/models/lfnet-asp-n2.json
  [lfnet-asp-n2-l3]=configs/models/lfnet-asp-n2.json
  [lfnet-asp-n2-l4]=configs/models/lfnet-asp-n2.json
  [lfnet-asp-n2]=configs/models/lfnet-asp-n2.json
  [lfnet-asp-n15]=configs/models/lfnet-asp-n15.json
  [lfnet-mask-n2]=configs/models/lfnet-mask-n2.json
)
declare -A init=(
  [lfnet-asp-n2-c32]=$first20
  [lfnet-asp-n2-c48]=models/lfnet-asp-n2-c32.ckpt
  [lfnet-asp-n2-f10]=models/lfnet-asp-n2-c48.ckpt
  [lfnet-asp-n2-l3]=models/lfnet-asp-n2-f10.ckpt
  [lfnet-asp-n2-l4]=models/lfnet-asp-n2-l3.ckpt
  [lfnet-asp-n2]=models/lfnet-asp-n2-l4.ckpt
  [lfnet-asp-n15]=$first20
  [lfnet-mask-n2]=$first20
)
# The 48-channel net on 4,500 crops of 64 x 64 per epoch: the steps that add frames.
frames_crops="--set network.image.channels=48 --set dataset.patch_h=64 --set dataset.patch_w=64
              --set network.patch.height=64 --set network.patch.width=64
              --set dataset.train_patches=4500"
# The 4-level net on 1,125 crops of 128 x 128 per epoch, frames in 70 % of the random scenes.
deep_crops="--set network.image.channels=48 --set network.image.levels=4
            --set network.image.widths=[48,96,192,128]
            --set data.random_options.frame_probability=0.7 --set dataset.patch_h=128
            --set dataset.patch_w=128 --set network.patch.height=128
            --set network.patch.width=128 --set dataset.train_patches=1125
            --set dataset.validation_fraction=0.5"
declare -A finetune=(
  [lfnet-asp-n2-c32]="--set training.epochs=30 --set training.lr=0.0004
                      --set data.random_seed=9000 --set dataset.seed=11"
  [lfnet-asp-n2-c48]="--set network.image.channels=48 --set training.epochs=14
                      --set training.lr=0.0003 --set data.random_seed=15000 --set dataset.seed=15"
  [lfnet-asp-n2-f10]="$frames_crops --set data.random_options.frame_probability=0.5
                      --set training.epochs=10 --set training.lr=0.0003 --set data.random_seed=17000
                      --set dataset.seed=17"
  [lfnet-asp-n2-l3]="$frames_crops --set data.random_options.frame_probability=0.7
                     --set training.epochs=14 --set training.lr=0.0001 --set data.random_seed=18000
                     --set dataset.seed=18"
  [lfnet-asp-n2-l4]="$deep_crops --set training.epochs=7 --set training.lr=0.0001
                     --set data.random_seed=21000 --set dataset.seed=21"
  [lfnet-asp-n2]="$deep_crops --set training.epochs=6 --set training.lr=0.00005
                  --set data.random_seed=24000 --set dataset.seed=24
                  --set distill.teacher=models/lfnet-asp-n2-l4.ckpt
                  --set distill.precision=bfloat16"
  [lfnet-asp-n15]="--set training.epochs=10 --set training.lr=0.0005"
  [lfnet-mask-n2]="--set training.epochs=10 --set training.lr=0.0005"
)
names=("$@")
[[ ${#names[@]} -eq 0 ]] && names=("${order[@]}")
for name in "${names[@]}"; do
  [[ -n ${config[$name]:-} ]] || { echo "unknown model '$name' (known: ${order[*]})" >&2; exit 2; }
  model=models/$name.ckpt
  out=out/lfnet-models/$name
  model_exists "$name" "$model" && continue
  if [[ -f $out/config.json ]]; then
    "$lfnet" --threads "$threads" train --resume "$out"
  else
    set -f  # the settings are split into words but not globbed: [48,96,192,128] is a list
    # shellcheck disable=SC2086
    "$lfnet" --threads "$threads" train "${config[$name]}" --scale paper --init "${init[$name]}" \
      ${finetune[$name]} --out "$out"
    set +f
  fi
  keep_model "$out" "$model"
  if [[ $name == lfnet-asp-n2* ]]; then  # the log holds every epoch since the first
    cat "${init[$name]%.ckpt}.training.jsonl" "$out/training.jsonl" \
      > "${model%.ckpt}.training.jsonl"
  else
    cp "$out/training.jsonl" "${model%.ckpt}.training.jsonl"
  fi
  echo "== $name: done ($(date -u +%H:%M))"
done
