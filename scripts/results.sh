#!/usr/bin/env bash
# Makes the records of results/<section>/records.jsonl, then regenerates docs/RESULTS.md with
# `lfnet report`. Usage: scripts/results.sh [SECTION...]   (default: every section below)
# Needs the trained models (models/, scripts/train-models.sh) and ../shared/data.
set -euo pipefail
cd "$(dirname "$0")/.."
lfnet=${LFNET:-build/apps/lfnet}
py=/usr/bin/python3

# Appends the JSON object of file $2 as one line to $1.
append_record() { "$py" -c 'import json,sys; print(json.dumps(json.load(open(sys.argv[1]))))' "$2" >> "$1"; }

heldout-asp-n2() {
  local dir=results/heldout-asp-n2 pics=out/results/heldout-asp-n2 tmp
  tmp=$(mktemp -d)
  rm -rf "$pics" && mkdir -p "$pics"
  : > "$tmp/records.jsonl"
  for mode in sensor per_patch; do
    for method in net ae cnn dict pinv adjoint no-parallax; do
      local extra=()
      [[ $mode == sensor ]] && extra=(--out "$pics/$method")
      "$lfnet" evaluate --model models/asp-n2.ckpt --dictionary models/dictionary.ckpt \
        --lf ../shared/data/hci_antinous --method "$method" --mode "$mode" --stride 5 \
        --json "$tmp/r.json" "${extra[@]}"
      append_record "$tmp/records.jsonl" "$tmp/r.json"
    done
  done
  mv "$tmp/records.jsonl" "$dir/records.jsonl"
  rm -rf "$tmp"
}

# One evaluation into $1 (records file): evaluate args follow.
record() {
  local file=$1 tmp
  shift
  tmp=$(mktemp)
  "$lfnet" evaluate "$@" --json "$tmp"
  append_record "$file" "$tmp"
  rm -f "$tmp"
}

# The paper's Fig. 5: ASP, mask and random projections at N = 2, stride 5. Random projections
# are measured per patch (their 9-pixel blocks do not tile a sensor at stride 5).
phi-comparison() {
  local tmp
  tmp=$(mktemp)
  for phi in asp mask random; do
    for method in net pinv no-parallax; do
      record "$tmp" --model "models/$phi-n2.ckpt" --lf ../shared/data/hci_antinous \
        --method "$method" --mode per_patch --stride 5
    done
  done
  mv "$tmp" results/phi-comparison/records.jsonl
}

# The paper's Table 1: ASP N = 2, 15, 25 on non-overlapping patches, against the dictionary.
compression-sweep() {
  local tmp
  tmp=$(mktemp)
  for n in 2 15 25; do
    for method in net dict pinv no-parallax; do
      record "$tmp" --model "models/asp-n$n.ckpt" --dictionary models/dictionary.ckpt \
        --lf ../shared/data/hci_antinous --method "$method" --mode sensor --stride 9
    done
  done
  mv "$tmp" results/compression-sweep/records.jsonl
}

# The paper's Table 2: Gaussian noise sigma 0, 0.1, 0.2 (relative to a white scene), ASP N = 2.
noise-sweep() {
  local tmp
  tmp=$(mktemp)
  for sigma in 0 0.1 0.2; do
    for method in net dict pinv no-parallax; do
      record "$tmp" --model models/asp-n2.ckpt --dictionary models/dictionary.ckpt \
        --lf ../shared/data/hci_antinous --method "$method" --mode sensor --stride 5 --noise "$sigma"
    done
  done
  mv "$tmp" results/noise-sweep/records.jsonl
}

# Seconds against PSNR over the stride: non-overlapping (9), 5, 2 and 1.
stride-sweep() {
  local tmp
  tmp=$(mktemp)
  for stride in 9 5 2 1; do
    local methods=(net cnn pinv no-parallax)
    # Stride 1 is 254,000 patches: the linear baselines only, to keep the run in minutes.
    [[ $stride == 1 ]] && methods=(pinv no-parallax)
    for method in "${methods[@]}"; do
      record "$tmp" --model models/asp-n2.ckpt --lf ../shared/data/hci_antinous \
        --method "$method" --mode sensor --stride "$stride"
    done
  done
  mv "$tmp" results/stride-sweep/records.jsonl
}

sections=("$@")
if [[ ${#sections[@]} -eq 0 ]]; then
  sections=(heldout-asp-n2 phi-comparison compression-sweep noise-sweep stride-sweep)
fi
for s in "${sections[@]}"; do
  echo "== $s"
  "$s"
done
"$lfnet" report results --out docs/RESULTS.md
