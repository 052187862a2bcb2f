#!/usr/bin/env bash
# Times the same whole-light-field evaluations with two lfnet programs, e.g. an older commit's
# build and this one's, case by case in alternation on the same machine, and prints a Markdown
# table: reconstruction seconds (the evaluation record), process CPU seconds and peak memory
# (/usr/bin/time), PSNR (equal PSNR means equal output), and the paper's time over ours.
# Usage: scripts/bench-before-after.sh BEFORE AFTER SCENE.json MODEL.ckpt [CASE...]
#   CASE = method:stride (default: net:9 net:5 ae:9 cnn:9 cnn:5 pinv:9 pinv:5 pinv:2 dict:9 dict:5)
#   DICTIONARY (env, default models/dictionary.ckpt) is used by dict; THREADS (default 2).
set -euo pipefail
cd "$(dirname "$0")/.."
[[ $# -ge 4 ]] || { sed -n 2,9p "$0"; exit 2; }
before=$1 after=$2 scene=$3 model=$4
shift 4
cases=("$@")
[[ ${#cases[@]} -gt 0 ]] || cases=(net:9 net:5 ae:9 cnn:9 cnn:5 pinv:9 pinv:5 pinv:2 dict:9 dict:5)
dictionary=${DICTIONARY:-models/dictionary.ckpt}
threads=${THREADS:-2}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# run LABEL PROGRAM METHOD STRIDE: one evaluation, its numbers as a tab-separated line.
run() {
  local label=$1 program=$2 method=$3 stride=$4
  /usr/bin/time -f "%U %S %M" -o "$tmp/time" "$program" --threads "$threads" --log-level warn \
    evaluate --scene "$scene" --model "$model" --dictionary "$dictionary" --method "$method" \
    --stride "$stride" --mode sensor --json "$tmp/r.json" > /dev/null 2> "$tmp/err" ||
    { echo "$label $method:$stride failed: $(tail -1 "$tmp/err")" >&2; return 1; }
  /usr/bin/python3 - "$tmp/r.json" "$tmp/time" "$label" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
user, system, kb = open(sys.argv[2]).read().split()[-3:]
paper = {"dict": 3786}.get(r["method"], 242)  # the paper's Titan X seconds at stride 5 (Table 2)
print("\t".join([sys.argv[3], r["method"], str(r["stride"]), str(r["patches"]), "%.2f" % r["seconds"],
                 "%.1f" % (float(user) + float(system)), "%.0f" % (int(kb) / 1024),
                 "%.2f" % r["psnr_db"], "%.1f x" % (paper / r["seconds"]) if r["stride"] == 5 and r["method"] in ("net", "dict") else ""]))
PY
}

echo "| code | method | stride | patches | seconds | process CPU s | peak MB | PSNR dB | paper / ours |"
echo "|---|---|---:|---:|---:|---:|---:|---:|---:|"
for c in "${cases[@]}"; do
  method=${c%%:*} stride=${c##*:}
  for side in before after; do
    program=$before
    [[ $side == after ]] && program=$after
    line=$(run "$side" "$program" "$method" "$stride") || continue
    echo "| ${line//$'\t'/ | } |"
  done
done
