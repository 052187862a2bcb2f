#!/usr/bin/env bash
# Trains the shipped models (configs/models/*.json) and copies them into models/.
# Usage: scripts/train-models.sh [--scale quick|paper] [NAME...]   (default: the quick-scale
# models mask-n2 random-n2 asp-n15 asp-n25; asp-n2 and dictionary ship at the paper scale:
# `scripts/train-models.sh --scale paper dictionary`, and asp-n2 resumably, docs/models.md)
# Each run goes to out/models/NAME; the model of the last stage becomes models/NAME.ckpt and
# its training log (one line per epoch) models/NAME.training.jsonl.
# Needs ../shared/data (the real light fields); hci_antinous is held out for evaluation.
set -euo pipefail
cd "$(dirname "$0")/.."
scale=quick
if [[ ${1:-} == --scale ]]; then scale=$2; shift 2; fi
names=("$@")
if [[ ${#names[@]} -eq 0 ]]; then names=(mask-n2 random-n2 asp-n15 asp-n25); fi
lfnet=${LFNET:-build/apps/lfnet}
mkdir -p models
for name in "${names[@]}"; do
  config=configs/models/$name.json
  out=out/models/$name
  echo "== $name ($config, scale $scale) -> $out"
  "$lfnet" train "$config" --scale "$scale" --out "$out" --force
  last=$(/usr/bin/python3 -c 'import json,sys; s=json.load(open(sys.argv[1]))["stages"][-1]; print(s if isinstance(s,str) else s["name"])' "$out/config.json")
  cp "$out/models/$last.ckpt" "models/$name.ckpt.tmp"
  mv "models/$name.ckpt.tmp" "models/$name.ckpt"
  [[ -f $out/training.jsonl ]] && cp "$out/training.jsonl" "models/$name.training.jsonl"
  ls -l "models/$name.ckpt"
done
