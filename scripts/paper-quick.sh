#!/usr/bin/env bash
# Trains the quick scale of the configs/paper/ experiments that the shipped models do not
# already cover, and keeps each final model with its training log in models/paper-quick/.
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
  [mask-from-asp]=configs/paper/phi-switching/mask-from-asp.json
  [mask-from-scratch]=configs/paper/phi-switching/mask-from-scratch.json
  [joint-from-scratch]=configs/paper/branch-ablation/joint-from-scratch.json
  [l2]=configs/paper/loss-ablation/l2.json
  [lytro]=configs/paper/lytro/asp-n2.json
  [noise-trained]=configs/paper/noise-sweep/asp-n2-noise-trained.json
  [noise-trained-0.2]=configs/paper/noise-sweep/asp-n2-noise-trained-0.2.json
)
declare -A extra=([mask-from-asp]="--init models/asp-n2.ckpt")
names=("$@")
if [[ ${#names[@]} -eq 0 ]]; then
  names=(mask-from-asp mask-from-scratch joint-from-scratch l2 lytro noise-trained noise-trained-0.2)
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
