#!/usr/bin/env bash
# Trains the quick scale of the configs/paper/ experiments and keeps each final model with its
# training log in models/paper-quick/: the paper's experiments compare these models, trained on
# one data set (which includes lytro_Begonia) with one schedule.
# Usage: scripts/paper-quick.sh [--collect] [NAME...]   (default: every NAME below)
#   --collect   only copy the models of runs already in out/paper-quick/ (no training)
# Each run goes to out/paper-quick/NAME (lfnet experiment: its own evaluations land in
# results.jsonl there); scripts/results.sh then evaluates the kept models for docs/RESULTS.md.
# Pass lfnet's global options in LFNET_OPTS, e.g. LFNET_OPTS="--threads 1" beside other work.
set -euo pipefail
cd "$(dirname "$0")/.."
lfnet=${LFNET:-build/apps/lfnet}
collect_only=0
if [[ ${1:-} == --collect ]]; then collect_only=1; shift; fi

# NAME -> config and extra arguments.
declare -A config=(
  [asp-n2]=configs/paper/compression-sweep/asp-n2.json
  [asp-n15]=configs/paper/compression-sweep/asp-n15.json
  [asp-n25]=configs/paper/compression-sweep/asp-n25.json
  [mask-n2]=configs/paper/phi-comparison/mask.json
  [random-n2]=configs/paper/phi-comparison/random.json
  [mask-from-asp]=configs/paper/phi-switching/mask-from-asp.json
  [mask-from-scratch]=configs/paper/phi-switching/mask-from-scratch.json
  [joint-from-scratch]=configs/paper/branch-ablation/joint-from-scratch.json
  [l2]=configs/paper/loss-ablation/l2.json
  [lytro]=configs/paper/lytro/asp-n2.json
  [noise-trained]=configs/paper/noise-sweep/asp-n2-noise-trained.json
  [noise-trained-0.2]=configs/paper/noise-sweep/asp-n2-noise-trained-0.2.json
)
declare -A extra=([mask-from-asp]="--init models/paper-quick/asp-n2.ckpt")
names=("$@")
if [[ ${#names[@]} -eq 0 ]]; then
  names=(asp-n2 asp-n15 asp-n25 mask-n2 random-n2 mask-from-asp mask-from-scratch joint-from-scratch l2 lytro noise-trained noise-trained-0.2)
fi
mkdir -p models/paper-quick
for name in "${names[@]}"; do
  [[ -n ${config[$name]:-} ]] || { echo "paper-quick.sh: unknown experiment '$name'" >&2; exit 2; }
  out=out/paper-quick/$name
  if [[ $collect_only == 0 ]]; then
    echo "== $name (${config[$name]}, quick scale) -> $out"
    # shellcheck disable=SC2086
    "$lfnet" ${LFNET_OPTS:-} experiment "${config[$name]}" --scale quick --out "$out" --force ${extra[$name]:-}
  fi
  last=$(/usr/bin/python3 -c 'import json,sys; s=json.load(open(sys.argv[1]))["stages"][-1]; print(s if isinstance(s,str) else s["name"])' "$out/config.json")
  cp "$out/models/$last.ckpt" "models/paper-quick/$name.ckpt.tmp"
  mv "models/paper-quick/$name.ckpt.tmp" "models/paper-quick/$name.ckpt"
  cp "$out/training.jsonl" "models/paper-quick/$name.training.jsonl"
  ls -l "models/paper-quick/$name.ckpt"
done
