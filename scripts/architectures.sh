#!/usr/bin/env bash
# The architecture search of docs/architectures.md: variants of lfnet's whole-image network
# (configs/models/lfnet-asp-n2.json with --set overrides), each trained at the config's quick
# scale and evaluated on the cross-scene benchmark's held-out light fields, beside pinv and
# no-parallax (variant "baseline"). Resumable: a variant whose run folder holds its results is
# not trained again. Usage: scripts/architectures.sh [VARIANT...]; LFNET_THREADS (default 1:
# it runs beside other work) sets --threads.
set -euo pipefail
cd "$(dirname "$0")/.."
lfnet=${LFNET:-build/apps/lfnet}
threads=${LFNET_THREADS:-1}
config=configs/models/lfnet-asp-n2.json
records=results/architectures/records.jsonl

# name -> the overrides that make it
declare -A variants=(
  [unet-c32-l3]="network.image.channels=32 network.image.levels=3 network.image.blocks=2"
  [unet-c32-l1]="network.image.channels=32 network.image.levels=1 network.image.blocks=2"
  [unet-c32-l3-b1]="network.image.channels=32 network.image.levels=3 network.image.blocks=1"
  [unet-c48-l4]="network.image.channels=48 network.image.levels=4 network.image.blocks=2"
)
order=(unet-c32-l1 unet-c32-l3-b1 unet-c32-l3 unet-c48-l4)
steps=("$@")
[[ ${#steps[@]} -eq 0 ]] && steps=("${order[@]}")
mkdir -p results/architectures
for name in "${steps[@]}"; do
  [[ -n ${variants[$name]+x} ]] || { echo "unknown variant '$name' (known: ${order[*]})" >&2; exit 2; }
  out=out/architectures/$name
  if [[ -f $out/results.jsonl ]]; then
    echo "== $name: $out/results.jsonl exists, skipped"
    continue
  fi
  echo "== $name: training ($(date -u +%H:%M))"
  sets=()
  for s in ${variants[$name]}; do sets+=(--set "$s"); done
  "$lfnet" --threads "$threads" --log-level warn experiment "$config" --scale quick \
    --out "$out" --force "${sets[@]}" --set network.image.noise_input=false \
    --set 'evaluation.methods=["net"]'
  scripts/label-records.py "$out" "$name" "$records"
  echo "== $name: done ($(date -u +%H:%M))"
done

# The baselines on the same light fields, once (they depend on the Phi alone).
if ! grep -qs '"variant": "baseline"' "$records"; then
  tmp=$(mktemp)
  for src in "--lf ../shared/data/hci_antinous" "--lf ../shared/data/lytro_Begonia" \
             "--scene configs/scenes/heldout_window.json" "--scene configs/scenes/heldout_wide.json"; do
    for method in pinv no-parallax; do
      # shellcheck disable=SC2086
      "$lfnet" --threads "$threads" --log-level warn evaluate --phi asp:2 $src --method "$method" \
        --mode sensor --stride 5 --json "$tmp"
      /usr/bin/python3 -c 'import json, sys; r = json.load(open(sys.argv[1])); r["variant"] = "baseline"; open(sys.argv[2], "a").write(json.dumps(r) + "\n")' "$tmp" "$records"
    done
  done
  rm -f "$tmp"
fi
