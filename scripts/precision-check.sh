#!/usr/bin/env bash
# Which models --precision auto may run in bfloat16 (docs/performance.md, "Precision auto"):
# evaluates each model in float32 and in bfloat16 on every light field of the cross-scene
# benchmark and writes models/bfloat16.json, where a model is verified when its PSNR in
# bfloat16 is within 0.05 dB of float32's on every one of them, measured on a CPU with native
# bfloat16 (the only kind on which auto runs bfloat16; emulated bfloat16 rounds differently).
# Usage: scripts/precision-check.sh [MODEL.ckpt...]   (default: the shipped lfnet models)
set -euo pipefail
cd "$(dirname "$0")/.."
lfnet=${LFNET:-build/apps/lfnet}
out=${PRECISION_LIST:-models/bfloat16.json}
models=("$@")
[[ ${#models[@]} -gt 0 ]] || models=(models/lfnet-asp-n2.ckpt models/lfnet-asp-n2-noise.ckpt \
  models/lfnet-asp-n15.ckpt models/lfnet-mask-n2.ckpt)
sources=("--lf ../shared/data/hci_antinous" "--lf ../shared/data/lytro_Begonia"
         "--scene configs/scenes/heldout_window.json" "--scene configs/scenes/heldout_wide.json")
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
: > "$tmp/records.jsonl"
for model in "${models[@]}"; do
  [[ -f $model ]] || { echo "precision-check.sh: $model is missing" >&2; exit 1; }
  for src in "${sources[@]}"; do
    for precision in float32 bfloat16; do
      # shellcheck disable=SC2086  # $src is a flag and its value
      "$lfnet" --log-level warn evaluate --model "$model" $src --mode sensor --method net \
        --precision "$precision" --json "$tmp/r.json" --force >/dev/null
      python3 -c 'import json, sys; r = json.load(open(sys.argv[1])); r["model"] = sys.argv[2]
print(json.dumps(r))' "$tmp/r.json" "$model" >> "$tmp/records.jsonl"
    done
  done
done
python3 - "$tmp/records.jsonl" "$out" "$*" <<'PY'
import json, os, sys, platform, collections
records = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
tolerance = 0.05

def fingerprint(path):  # FNV-1a 64, as lfnet's nn::file_fingerprint
    h = 14695981039346656037
    with open(path, "rb") as f:
        for b in f.read():
            h = ((h ^ b) * 1099511628211) & 0xFFFFFFFFFFFFFFFF
    return f"{h:016x}"

cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")), platform.machine())
flags = next((l.split(":", 1)[1].split() for l in open("/proc/cpuinfo") if l.startswith("flags")), [])
native = "avx512_bf16" in flags or "amx_bf16" in flags
out_path = sys.argv[2]
doc = json.load(open(out_path)) if os.path.exists(out_path) else {}
doc.update({
    "what": "models that lfnet --precision auto may run in bfloat16: PSNR in bfloat16 within "
            "tolerance_db of float32 on every light field of the cross-scene benchmark",
    "tolerance_db": tolerance,
    "command": "scripts/precision-check.sh " + (sys.argv[3] or "(the shipped lfnet models)"),
    "measured_on": cpu + (" (native bfloat16)" if native else " (bfloat16 emulated: no native bfloat16)"),
})
models = doc.setdefault("models", {})
by_model = collections.defaultdict(dict)
for r in records:
    by_model[r["model"]].setdefault(r["light_field"], {})[r["precision"]] = r["psnr_db"]
for model, per_lf in by_model.items():
    drops = {lf: round(p["float32"] - p["bfloat16"], 4) for lf, p in per_lf.items()}
    worst = max(drops.values())
    models[os.path.basename(model)] = {
        "fingerprint": fingerprint(model),
        "psnr_float32_db": {lf: round(p["float32"], 4) for lf, p in per_lf.items()},
        "drop_db": drops,
        "max_drop_db": worst,
        "verified": worst <= tolerance and native,
    }
    print(f"{model}: largest bfloat16 drop {worst:+.4f} dB -> "
          f"{'verified' if worst <= tolerance and native else 'not verified'}"
          + ("" if native else " (no native bfloat16 here)"))
tmp = out_path + ".tmp"
with open(tmp, "w") as f:
    f.write(json.dumps(doc, indent=2) + "\n")
os.replace(tmp, out_path)
print("wrote", out_path)
PY
