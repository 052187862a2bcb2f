#!/usr/bin/env bash
# The training-data ablation of docs/models.md: configs/generalisation/g0..g4, each adding one
# change to the data of the one before (natural-image textures, disparities to +-4 px, angular
# windows, photometric jitter), trained at the quick scale and evaluated on the cross-scene
# benchmark's held-out light fields. Resumable: a step whose model (its recipe's, in
# out/cache/generalisation/) exists is not trained again. Usage:
# scripts/generalisation-ablation.sh [STEP...]; LFNET_THREADS (default 1: it runs beside other
# work) sets --threads.
set -euo pipefail
cd "$(dirname "$0")/.."
lfnet=${LFNET:-build/apps/lfnet}
threads=${LFNET_THREADS:-1}
steps=("$@")
[[ ${#steps[@]} -eq 0 ]] && steps=(g0-baseline g1-natural-textures g2-disparity-4 g3-angular-windows g4-jitter)
mkdir -p results/generalisation-ablation
for step in "${steps[@]}"; do
  model=out/cache/generalisation/$step.ckpt
  if [[ -f $model ]]; then
    echo "== $step: $model exists, skipped"
    continue
  fi
  echo "== $step: training ($(date -u +%H:%M))"
  # Its recipe (configs/recipes.json): lfnet experiment, resumable, into out/models/.
  out=out/models/generalisation/$step
  LFNET=$lfnet LFNET_THREADS=$threads scripts/models.py make "generalisation/$step"
  # The step's cross-scene records, labelled with the step and its training time.
  scripts/label-records.py "$out" "$step" "results/generalisation-ablation/records.jsonl"
  echo "== $step: done ($(date -u +%H:%M))"
done

# The baselines on the same light fields, once (they depend on the Phi alone).
records=results/generalisation-ablation/records.jsonl
if ! grep -q '"variant": "baseline"' "$records"; then
  tmp=$(mktemp)
  for src in "--lf ../shared/data/hci_antinous" "--lf ../shared/data/lytro_Begonia" \
             "--scene configs/scenes/heldout_window.json" "--scene configs/scenes/heldout_wide.json"; do
    for method in pinv no-parallax; do
      # shellcheck disable=SC2086
      "$lfnet" --threads "$threads" --log-level warn evaluate --model out/cache/generalisation/g0-baseline.ckpt \
        $src --method "$method" --mode sensor --stride 5 --json "$tmp"
      /usr/bin/python3 -c 'import json, sys; r = json.load(open(sys.argv[1])); r["variant"] = "baseline"; open(sys.argv[2], "a").write(json.dumps(r) + "\n")' "$tmp" "$records"
    done
  done
  rm -f "$tmp"
fi
