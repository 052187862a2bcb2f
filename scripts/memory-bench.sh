#!/bin/bash
# Peak memory against light-field size: simulate, reconstruct (lfnet-asp-n2 and pinv), evaluate
# and batch on 5 x 5 grey light fields of 0.5, 2, 6 and 12 megapixels per view (2:3, 16-bit
# PNG views of a textured plane with parallax, made once into $MEMORY_BENCH_DATA), each command
# run alone with --out where it has one. Writes results/memory/records.jsonl (one record per
# command and size: peak resident set in MB from wait4's ru_maxrss, wall seconds) and prints
# the table that docs/performance.md ("Peak memory against size") holds, and draws
# docs/images/memory.png.
# Usage: scripts/memory-bench.sh [BINARY]   (SIZES="0.5 2" to measure fewer sizes; RECORDS=FILE
# to write the records elsewhere and draw no figure, e.g. for an older build)
set -euo pipefail
cd "$(dirname "$0")/.."
lfnet=$(realpath "${1:-build/apps/lfnet}")
data=${MEMORY_BENCH_DATA:-/tmp/lfnet-memory-bench}
sizes=(${SIZES:-0.5 2 6 12})
model=models/lfnet-asp-n2.ckpt
py=/usr/bin/python3
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
records=${RECORDS:-results/memory/records.jsonl}
plot=docs/images/memory.png
[[ -n ${RECORDS:-} ]] && plot=""
mkdir -p "$data" "$(dirname "$records")"
: > "$work/records.jsonl"

# A 5 x 5 light field of MP megapixels per view: a random texture (smooth and fine detail) seen
# with a disparity of 1 pixel per view, written once.
make_light_field() {
  local dir=$1 mp=$2
  [[ -f $dir/lf_5_5.png ]] && return 0
  mkdir -p "$dir"
  "$py" - "$dir" "$mp" <<'PY'
import sys, numpy as np
from PIL import Image
out, mp = sys.argv[1], float(sys.argv[2])
h = int(round((mp * 1e6 * 2 / 3) ** 0.5)); w = int(round(h * 1.5))
rng = np.random.default_rng(0)
coarse = rng.random((h // 16 + 3, w // 16 + 3)).astype(np.float32)
base = np.array(Image.fromarray(coarse).resize((w + 64, h + 64), Image.BICUBIC))
tex = np.clip(0.6 * base + 0.4 * rng.random((h + 64, w + 64), dtype=np.float32), 0, 1)
for u in range(5):
    for v in range(5):
        view = tex[32 + (u - 2): 32 + (u - 2) + h, 32 + (v - 2): 32 + (v - 2) + w]
        Image.fromarray((view * 65535 + 0.5).astype(np.uint16)).save(f"{out}/lf_{u + 1}_{v + 1}.png")
PY
}

# Runs one lfnet command and appends its record: name, size, then the command's arguments.
measure() {
  local name=$1 mp=$2
  shift 2
  "$py" - "$name" "$mp" "$work/records.jsonl" "$lfnet" --threads 2 --log-level warn "$@" <<'PY'
import json, os, subprocess, sys, time
name, mp, out, cmd = sys.argv[1], float(sys.argv[2]), sys.argv[3], sys.argv[4:]
start = time.monotonic()
proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL)
_, status, usage = os.wait4(proc.pid, 0)
seconds = time.monotonic() - start
rc = os.waitstatus_to_exitcode(status)
rec = {"command": name, "megapixels": mp, "peak_mb": round(usage.ru_maxrss / 1024, 1),
       "seconds": round(seconds, 2), "exit": rc, "args": " ".join(cmd[5:])}
print(f"{name:<22} {mp:>5} MP  {rec['peak_mb']:>8.0f} MB  {seconds:>7.1f} s" +
      ("" if rc == 0 else f"  FAILED ({rc})"), flush=True)
open(out, "a").write(json.dumps(rec) + "\n")
PY
}

for mp in "${sizes[@]}"; do
  lf=$data/mp$mp
  make_light_field "$lf" "$mp"
  rm -rf "$work/acq" "$work/rec" "$work/pinv" "$work/eval" "$work/batch" "$work/items" \
    "$work"/eval*.json
  measure simulate "$mp" simulate --lf "$lf" --phi "$model" --out "$work/acq"
  measure "reconstruct net" "$mp" reconstruct --model "$model" --sensor "$work/acq" \
    --out "$work/rec"
  measure "reconstruct pinv" "$mp" reconstruct --method pinv --sensor "$work/acq" \
    --out "$work/pinv"
  measure "evaluate net" "$mp" evaluate --model "$model" --lf "$lf" --json "$work/eval.json" \
    --out "$work/eval"
  measure "evaluate pinv" "$mp" evaluate --phi asp:2 --method pinv --lf "$lf" \
    --json "$work/eval-pinv.json"
  mkdir -p "$work/items" && ln -s "$lf" "$work/items/lf"
  measure "batch net" "$mp" batch --in "$work/items" --model "$model" --out "$work/batch"
done
mv "$work/records.jsonl" "$records"

"$py" - "$records" "$plot" <<'PY'
import json, sys
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
rows = [json.loads(l) for l in open(sys.argv[1])]
commands = list(dict.fromkeys(r["command"] for r in rows))
sizes = sorted({r["megapixels"] for r in rows})
by = {(r["command"], r["megapixels"]): r for r in rows}
print("| command | " + " | ".join(f"{s:g} MP" for s in sizes) + " |")
print("|---|" + "---:|" * len(sizes))
for c in commands:
    cells = []
    for s in sizes:
        r = by.get((c, s))
        cells.append("" if r is None else
                     (f"{r['peak_mb']:.0f} MB, {r['seconds']:.1f} s" if r["exit"] == 0 else "failed"))
    print(f"| {c} | " + " | ".join(cells) + " |")
if not sys.argv[2]:
    sys.exit(0)
fig, ax = plt.subplots(figsize=(8, 4))
for c in commands:
    pts = [(s, by[(c, s)]["peak_mb"]) for s in sizes if (c, s) in by and by[(c, s)]["exit"] == 0]
    ax.plot([p[0] for p in pts], [p[1] for p in pts], marker="o", label=c)
ax.axhline(2048, color="grey", linestyle="--", linewidth=1)
ax.text(sizes[-1], 2048, "2 GB ", va="bottom", ha="right", color="grey")
ax.set_xlabel("megapixels per view (5 x 5 grey views)")
ax.set_ylabel("peak resident memory (MB)")
ax.set_title("Peak memory against light-field size")
ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1))
ax.grid(alpha=0.3)
fig.tight_layout()
fig.savefig(sys.argv[2], dpi=110)
PY
