#!/usr/bin/env bash
# Where the noise switch of models/lfnet-asp-n2-auto.json goes over from its quiet member to its
# noise-aware one (docs/models.md, "One model for any noise"): on three random scenes of lfnet's
# generator that no model trained on and no benchmark uses (seeds 91001 to 91003, 376 x 541,
# disparities -3 to 3 px per view step, frames as in training), both members (the noise-aware one
# told the true sigma) at Gaussian sigmas from 0 to 0.03, and the sigma the estimator finds in the
# noiseless sensor images, beside no-parallax. The switch sigma is chosen from these records
# alone (never from the cross-scene benchmark or the test set). Writes
# results/noise-switch/records.jsonl; the members are the switch file's (SWITCH, default
# models/lfnet-asp-n2-auto.json).
set -euo pipefail
cd "$(dirname "$0")/.."
lfnet=${LFNET:-build/apps/lfnet}
threads=${THREADS:-2}
switch=${SWITCH:-models/lfnet-asp-n2-auto.json}
member() { /usr/bin/python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))[sys.argv[2]].removesuffix(".ckpt"))' "$switch" "$1"; }
quiet=$(member quiet)
noisy=$(member noisy)
scenes=$(mktemp -d)
records=$(mktemp)
trap 'rm -rf "$scenes" "$records.one"' EXIT
for seed in 91001 91002 91003; do
  "$lfnet" --threads "$threads" --log-level warn render --random "$seed" --size 376x541 \
    --disparity-range -3:3 --random-options '{"frame_probability": 0.7}' --grey --bits 16 \
    --out "$scenes/random-$seed"
  for sigma in 0 0.0025 0.005 0.0075 0.01 0.0125 0.015 0.02 0.03; do
    for model in "$quiet" "$noisy"; do
      "$lfnet" --threads "$threads" --log-level warn evaluate --model "models/$model.ckpt" \
        --lf "$scenes/random-$seed" --method net --mode sensor --noise "$sigma" \
        --json "$records.one" --force
      /usr/bin/python3 - "$records" "$records.one" "$model" "$seed" <<'PY'
import json, sys
r = json.load(open(sys.argv[2]))
r["variant"] = sys.argv[3]
r["light_field"] = "random-" + sys.argv[4]
open(sys.argv[1], "a").write(json.dumps(r) + "\n")
PY
    done
  done
  # The trivial baseline: the truth's angular mean (no noise at any sigma).
  "$lfnet" --threads "$threads" --log-level warn evaluate --phi asp:2 \
    --lf "$scenes/random-$seed" --method no-parallax --mode sensor --json "$records.one" --force
  /usr/bin/python3 - "$records" "$records.one" "$seed" <<'PY'
import json, sys
r = json.load(open(sys.argv[2]))
r["light_field"] = "random-" + sys.argv[3]
open(sys.argv[1], "a").write(json.dumps(r) + "\n")
PY
  # What the estimator reads in the noiseless sensor image.
  "$lfnet" --threads "$threads" --log-level warn evaluate --model "models/$noisy.ckpt" \
    --lf "$scenes/random-$seed" --method net --mode sensor --estimate-noise --json "$records.one" --force
  /usr/bin/python3 - "$records" "$records.one" "$seed" "$noisy" <<'PY'
import json, sys
r = json.load(open(sys.argv[2]))
r["variant"] = sys.argv[4] + ", estimated"
r["light_field"] = "random-" + sys.argv[3]
open(sys.argv[1], "a").write(json.dumps(r) + "\n")
PY
done
mv "$records" results/noise-switch/records.jsonl
# The switch: where the noise-aware member's mean PSNR over the scenes first exceeds the quiet
# member's, interpolated linearly between the sigmas measured.
/usr/bin/python3 - results/noise-switch/records.jsonl "$quiet" "$noisy" <<'PY'
import collections, json, sys
quiet, noisy = sys.argv[2], sys.argv[3]
psnr = collections.defaultdict(list)
for line in open(sys.argv[1]):
    r = json.loads(line)
    if r.get("variant") in (quiet, noisy):
        psnr[(r["variant"], r["noise_sigma"])].append(r["psnr_db"])
gain = []
for sigma in sorted({s for _, s in psnr}):
    mean = lambda v: sum(psnr[(v, sigma)]) / len(psnr[(v, sigma)])
    gain.append((sigma, mean(noisy) - mean(quiet)))
    print(f"sigma {sigma:<7g} {noisy} minus {quiet}: {gain[-1][1]:+.3f} dB")
for (s0, g0), (s1, g1) in zip(gain, gain[1:]):
    if g0 < 0 <= g1:
        print(f"switch sigma: {s0 + (s1 - s0) * -g0 / (g1 - g0):.4f}")
        break
PY
