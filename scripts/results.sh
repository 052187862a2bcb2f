#!/usr/bin/env bash
# Makes the records of results/<section>/records.jsonl, then regenerates docs/RESULTS.md with
# `lfnet report`. Usage: scripts/results.sh [SECTION...]   (default: every section below;
# `pictures` remakes only the reconstructions the report shows, and `report` nothing;
# `MODELS="models/X.ckpt ..." scripts/results.sh cross-scene-add` adds networks to the
# cross-scene table without measuring the others again).
# Needs the zoo's models (models/), the research models their recipes make into out/cache/
# (scripts/models.py make NAME; need_model names the recipe of a missing one) and ../shared/data.
set -euo pipefail
cd "$(dirname "$0")/.."
lfnet=${LFNET:-build/apps/lfnet}
py=/usr/bin/python3

# Appends the JSON object of file $2 as one line to $1. With $3, the record's "variant"; with
# $4 (a training.jsonl), "training_seconds": the sum of its epochs' seconds.
append_record() {
  "$py" - "$@" <<'PY'
import json, os, sys
out, path = sys.argv[1], sys.argv[2]
r = json.load(open(path))
if len(sys.argv) > 3 and sys.argv[3]:
    r["variant"] = sys.argv[3]
if len(sys.argv) > 4 and sys.argv[4]:
    r["training_seconds"] = sum(json.loads(l)["record"]["seconds"] for l in open(sys.argv[4]) if l.strip())
if os.environ.get("RUN"):
    r["run"] = os.environ["RUN"]
open(out, "a").write(json.dumps(r) + "\n")
PY
}

# The paper's experiments (configs/paper/) compare quick-scale models of one schedule and one
# data set; their recipes make them into out/cache/paper-quick/ (scripts/models.py make NAME),
# most with their training logs.
pq=out/cache/paper-quick

heldout-asp-n2() {
  local dir=results/heldout-asp-n2 pics=out/results/heldout-asp-n2 tmp
  tmp=$(mktemp -d)
  rm -rf "$pics" && mkdir -p "$pics"
  : > "$tmp/records.jsonl"
  for mode in sensor per_patch; do
    for method in net ae cnn dict pinv adjoint no-parallax; do
      local extra=()
      [[ $mode == sensor ]] && extra=(--out "$pics/$method")
      "$lfnet" evaluate --model "$(model_file asp-n2)" --dictionary "$(model_file dictionary)" \
        --lf ../shared/data/hci_antinous --method "$method" --mode "$mode" --stride 5 \
        --json "$tmp/r.json" "${extra[@]}"
      append_record "$tmp/records.jsonl" "$tmp/r.json"
    done
  done
  mv "$tmp/records.jsonl" "$dir/records.jsonl"
  rm -rf "$tmp"
}

# Replaces the records of records file $1 whose variant is among those of records file $2 by
# $2's records.
replace_variants() {
  "$py" - "$1" "$2" <<'PY'
import json, sys
old_path, new_path = sys.argv[1], sys.argv[2]
new = [json.loads(l) for l in open(new_path) if l.strip()]
variants = {r.get("variant") for r in new}
kept = [l for l in open(old_path) if l.strip() and json.loads(l).get("variant") not in variants]
with open(old_path + ".tmp", "w") as f:
    f.writelines(kept)
    f.writelines(json.dumps(r) + "\n" for r in new)
PY
  mv "$1.tmp" "$1"
}

# Stops the run unless model file $1 exists: a section never loses rows silently.
# The file of model NAME (a path under models/ without .ckpt): the zoo's file in models/, else
# the research model that its recipe makes into out/cache/ (scripts/models.py make).
model_file() {
  if [[ -f models/$1.ckpt ]]; then echo "models/$1.ckpt"; else echo "out/cache/$1.ckpt"; fi
}

# The training log beside model NAME's file.
model_log() {
  local file
  file=$(model_file "$1")
  echo "${file%.ckpt}.training.jsonl"
}

need_model() {
  if [[ ! -f $1 ]]; then
    local recipe
    recipe=$("$py" -c 'import json, sys
print(" ".join(r["name"] for r in json.load(open("configs/recipes.json"))["recipes"]
               if r["model"] == sys.argv[1]) or "?")' "$1")
    echo "results.sh: $1 is missing, so ${FUNCNAME[1]} would lose its rows; make it first:" \
      "scripts/models.py make $recipe" >&2
    exit 1
  fi
}

# One evaluation into $1 (records file): evaluate args follow. $VARIANT and $TRAINING (a
# training.jsonl), when set, label the record (append_record).
record() {
  local file=$1 tmp
  shift
  tmp=$(mktemp)
  "$lfnet" evaluate "$@" --json "$tmp"
  append_record "$file" "$tmp" "${VARIANT:-}" "${TRAINING:-}"
  rm -f "$tmp"
}

# The paper's Fig. 5: ASP, mask and random projections at N = 2, stride 5. Random projections
# are measured per patch (their 9-pixel blocks do not tile a sensor at stride 5).
phi-comparison() {
  local tmp
  tmp=$(mktemp)
  for phi in asp mask random; do
    for method in net pinv no-parallax; do
      record "$tmp" --model "$pq/$phi-n2.ckpt" --lf ../shared/data/hci_antinous \
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
      record "$tmp" --model "$pq/asp-n$n.ckpt" --dictionary "$(model_file dictionary)" \
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
    for method in net dict pinv pinv-nlm no-parallax; do
      local variant=""
      [[ $method == net || $method == dict ]] && variant="trained without noise"
      VARIANT=$variant record "$tmp" --model $pq/asp-n2.ckpt \
        --dictionary "$(model_file dictionary)" --lf ../shared/data/hci_antinous --method "$method" \
        --mode sensor --stride 5 --noise "$sigma"
    done
    VARIANT="trained at sigma 0.1" record "$tmp" --model $pq/noise-trained.ckpt \
      --lf ../shared/data/hci_antinous --method net --mode sensor --stride 5 --noise "$sigma"
    VARIANT="trained at sigma 0.2" record "$tmp" --model $pq/noise-trained-0.2.ckpt \
      --lf ../shared/data/hci_antinous --method net --mode sensor --stride 5 --noise "$sigma"
    # lfnet's architecture (scripts/models.py): without noise, noise-aware, one sigma.
    local name model
    for name in lfnet-asp-n2 lfnet-asp-n2-first20 lfnet-asp-n2-noise lfnet-noise/aware-s0.025 \
      lfnet-noise/aware-s0.1 lfnet-noise/sigma-0.1 lfnet-noise/sigma-0.2; do
      model="$(model_file "$name")"
      need_model "$model"
      case $name in
        lfnet-asp-n2) variant="lfnet-asp-n2, trained without noise" ;;
        lfnet-asp-n2-first20) variant="lfnet-asp-n2-first20, without noise: the noise models' start" ;;
        lfnet-asp-n2-noise) variant="lfnet-asp-n2-noise, noise-aware" ;;
        lfnet-noise/aware-s0.025) variant="lfnet, noise-aware, its first 8 epochs (s = 0.025)" ;;
        lfnet-noise/aware-s0.1) variant="lfnet, noise-aware, its first 16 epochs (then s = 0.1)" ;;
        *) variant="lfnet, trained at sigma ${name#lfnet-noise/sigma-}" ;;
      esac
      VARIANT=$variant record "$tmp" --model "$model" --lf ../shared/data/hci_antinous \
        --method net --mode sensor --stride 5 --noise "$sigma"
    done
  done
  mv "$tmp" results/noise-sweep/records.jsonl
}

# Shot and read noise (configs/sensors/): the noise-aware lfnet models against one-sigma ones,
# the noiseless one and the baselines, on hci_antinous.
sensor-noise() {
  local tmp sensor method name model i
  tmp=$(mktemp)
  need_model "$(model_file lfnet-asp-n2-robust)"
  for ((i = 0; i < ${#heldout[@]}; i += 2)); do
    for sensor in daylight indoor dim; do
      local src=("${heldout[@]:i:2}" --mode sensor --effects configs/sensors/$sensor.json)
      for method in pinv pinv-nlm no-parallax; do
        record "$tmp" --phi asp:2 "${src[@]}" --method "$method"
      done
      local names=(lfnet-asp-n2 lfnet-asp-n2-noise lfnet-asp-n2-robust)
      # The models trained at one noise level, and on Gaussian noise alone, on the first only.
      ((i == 0)) && names+=(lfnet-noise/aware-s0.1 lfnet-noise/sigma-0.1 lfnet-noise/sigma-0.2)
      for name in "${names[@]}"; do
        model="$(model_file "$name")"
        need_model "$model"
        VARIANT=$name record "$tmp" --model "$model" "${src[@]}" --method net
      done
      VARIANT="lfnet-asp-n2-robust, estimated" record "$tmp" \
        --model "$(model_file lfnet-asp-n2-robust)" "${src[@]}" --method net --estimate-noise
      VARIANT="lfnet-asp-n2-auto, estimated" record "$tmp" \
        --model models/lfnet-asp-n2-auto.json "${src[@]}" --method net --estimate-noise
    done
  done
  mv "$tmp" results/sensor-noise/records.jsonl
}

# Noise-blind (docs/acquisition.md, "Estimating the noise"): on the light fields of the
# cross-scene benchmark at sigma 0, 0.05, 0.1 and 0.2, the noise-aware model told the true sigma
# and told the sigma estimated from the sensor image, beside the noise-unaware default, pinv and
# pinv-nlm (told the sigma) and no-parallax; and the noise switch lfnet-asp-n2-auto (the default
# below the estimated sigma 0.0077, the noise-aware model above), never told.
noise-blind() {
  local tmp i sigma
  tmp=$(mktemp)
  need_model "$(model_file lfnet-asp-n2-noise)"
  need_model "$(model_file lfnet-asp-n2-robust)"
  for ((i = 0; i < ${#heldout[@]}; i += 2)); do
    local src=("${heldout[@]:i:2}" --mode sensor)
    for sigma in 0 0.05 0.1 0.2; do
      for method in pinv pinv-nlm no-parallax; do
        record "$tmp" --phi asp:2 "${src[@]}" --method "$method" --noise "$sigma"
      done
      VARIANT=lfnet-asp-n2 record "$tmp" --model "$(model_file lfnet-asp-n2)" "${src[@]}" \
        --method net --noise "$sigma"
      VARIANT="lfnet-asp-n2-noise, told" record "$tmp" --model "$(model_file lfnet-asp-n2-noise)" \
        "${src[@]}" --method net --noise "$sigma"
      VARIANT="lfnet-asp-n2-noise, estimated" record "$tmp" \
        --model "$(model_file lfnet-asp-n2-noise)" "${src[@]}" --method net --noise "$sigma" \
        --estimate-noise
      VARIANT="lfnet-asp-n2-robust, told" record "$tmp" --model "$(model_file lfnet-asp-n2-robust)" \
        "${src[@]}" --method net --noise "$sigma"
      VARIANT="lfnet-asp-n2-robust, estimated" record "$tmp" \
        --model "$(model_file lfnet-asp-n2-robust)" "${src[@]}" --method net --noise "$sigma" \
        --estimate-noise
      VARIANT="lfnet-asp-n2-auto, estimated" record "$tmp" --model models/lfnet-asp-n2-auto.json \
        "${src[@]}" --method net --noise "$sigma" --estimate-noise
    done
  done
  mv "$tmp" results/noise-blind/records.jsonl
}

# The validation and test sets (docs/protocol.md, configs/sets/), made into out/sets/, and on
# every light field of both: the grey default, its noise-aware sibling and the learned codes
# against pinv and no-parallax; the noise switch told nothing (noiseless, and at sigma 0.05
# against pinv-nlm told it); the colour
# sibling behind an RGGB array against pinv with either demosaic. ASP N = 2 (the learned codes
# their own camera), sensor mode; the noisy-views light fields carry their noise in the truth.
# scripts/holdout-margins.py prints the margins, per light field and as each set's worst case.
# The candidates that were not shipped join with holdout-add (grey) and holdout-colour-add
# (colour) after `scripts/models.py make NAME` (their models go to out/hard/).
holdout_sets() {
  local s
  for s in validation test; do
    "$lfnet" sets make "configs/sets/$s.json" --out "out/sets/$s" --force
  done
}

# Appends to $1 the records of the grey network $2 (a model path; its variant the file's name)
# on light-field folder $3.
holdout_net() {
  local name
  name=$(basename "$2" .ckpt)
  VARIANT=$name record "$1" --model "$2" --lf "$3" --method net --mode sensor --stride 5
}

holdout() {
  local tmp dir m
  need_model "$(model_file lfnet-asp-n2)"
  need_model "$(model_file lfnet-asp-n2-bayer-blend)"
  holdout_sets
  tmp=$(mktemp)
  for dir in out/sets/validation/* out/sets/test/*; do
    [[ -f $dir/set.json ]] || continue
    local src=(--lf "$dir" --mode sensor --stride 5)
    for method in no-parallax pinv; do
      record "$tmp" --phi asp:2 "${src[@]}" --method "$method"
    done
    for m in "$(model_file lfnet-asp-n2)" "$(model_file lfnet-asp-n2-noise)" \
      "$(model_file lfnet-asp-n2-hard-blend)" "$(model_file lfnet-learned-mask-n2-full-l3)" \
      "$(model_file lfnet-learned-asp-n2-full)"; do
      holdout_net "$tmp" "$m" "$dir"
    done
    for sigma in 0 0.05; do
      VARIANT="lfnet-asp-n2-auto, estimated" record "$tmp" \
        --model models/lfnet-asp-n2-auto.json "${src[@]}" --method net --noise "$sigma" \
        --estimate-noise
    done
    holdout_told "$tmp" "$dir"
    record "$tmp" --phi asp:2 "${src[@]}" --method pinv-nlm --noise 0.05
    VARIANT="Bayer RGGB, blend" record "$tmp" "${src[@]}" \
      --model "$(model_file lfnet-asp-n2-bayer-blend)" --cfa RGGB
    VARIANT="Bayer RGGB" record "$tmp" --phi asp:2 "${src[@]}" --method pinv --cfa RGGB
    VARIANT="Bayer RGGB, malvar" record "$tmp" --phi asp:2 "${src[@]}" --method pinv --cfa RGGB \
      --demosaic malvar
  done
  mv "$tmp" results/holdout/records.jsonl
}

# Appends to $1 the noise switch told sigma 0.05 on light-field folder $2.
holdout_told() {
  VARIANT="lfnet-asp-n2-auto, told" record "$1" --model models/lfnet-asp-n2-auto.json --lf "$2" \
    --mode sensor --method net --noise 0.05
}

# Adds the colour networks of $MODELS (checkpoint paths, behind RGGB) to the holdout records,
# each as variant "Bayer RGGB, NAME", replacing the records of the same variant.
holdout-colour-add() {
  local tmp dir model name
  read -r -a models <<< "${MODELS:?MODELS names the checkpoints to add}"
  tmp=$(mktemp)
  for dir in out/sets/validation/* out/sets/test/*; do
    [[ -f $dir/set.json ]] || continue
    for model in "${models[@]}"; do
      need_model "$model"
      name=$(basename "$model" .ckpt)
      VARIANT="Bayer RGGB, $name" record "$tmp" --model "$model" --lf "$dir" --mode sensor \
        --cfa RGGB
    done
  done
  replace_variants results/holdout/records.jsonl "$tmp"
  rm -f "$tmp"
}

# The holdout records of the noise switch told the sigma, made again.
holdout-told() {
  local tmp dir
  tmp=$(mktemp)
  for dir in out/sets/validation/* out/sets/test/*; do
    [[ -f $dir/set.json ]] && holdout_told "$tmp" "$dir"
  done
  replace_variants results/holdout/records.jsonl "$tmp"
  rm -f "$tmp"
}

# Adds the grey networks of $MODELS (checkpoint paths, space-separated) to the holdout records,
# replacing the records of the same variant.
holdout-add() {
  local tmp dir model
  read -r -a models <<< "${MODELS:?MODELS names the checkpoints to add}"
  [[ -d out/sets/test ]] || holdout_sets
  tmp=$(mktemp)
  for dir in out/sets/validation/* out/sets/test/*; do
    [[ -f $dir/set.json ]] || continue
    for model in "${models[@]}"; do
      need_model "$model"
      holdout_net "$tmp" "$model" "$dir"
    done
  done
  replace_variants results/holdout/records.jsonl "$tmp"
  rm -f "$tmp"
}

# A colour sensor behind a Bayer colour filter array (docs/acquisition.md, "Colour filter
# arrays"): on the colour light fields of the cross-scene benchmark, pinv of the mosaicked
# sensor image, each view then demosaiced, against the grey pinv of a grey sensor and the
# colour no-parallax; colour PSNR and luma PSNR. Against them the colour networks
# lfnet-asp-n2-bayer-blend (lfnet-asp-n2-bayer-distilled blended with the grey default it was
# finetuned from; one pass and its self-ensemble), lfnet-asp-n2-bayer-distilled (one pass and
# its self-ensemble), lfnet-asp-n2-bayer-malvar (its
# teacher) and lfnet-asp-n2-bayer, which reconstruct the colours with the views from the same
# sensor image, and the grey default on a grey sensor; pinv also with the gradient-corrected
# (malvar) demosaic.
colour() {
  local tmp i
  need_model "$(model_file lfnet-asp-n2-bayer)"
  need_model "$(model_file lfnet-asp-n2-bayer-malvar)"
  need_model "$(model_file lfnet-asp-n2-bayer-distilled)"
  need_model "$(model_file lfnet-asp-n2-bayer-blend)"
  tmp=$(mktemp)
  for ((i = 0; i < ${#heldout[@]}; i += 2)); do
    local src=("${heldout[@]:i:2}" --mode sensor --phi asp:2)
    local kind
    for kind in distilled blend; do
      local net=(--model "$(model_file "lfnet-asp-n2-bayer-$kind")" --cfa RGGB)
      local log="$(model_log "lfnet-asp-n2-bayer-$kind")"
      VARIANT="Bayer RGGB, $kind" TRAINING=$log record "$tmp" "${src[@]}" "${net[@]}"
      VARIANT="Bayer RGGB, $kind, self-ensemble" TRAINING=$log \
        record "$tmp" "${src[@]}" "${net[@]}" --self-ensemble
    done
    VARIANT="Bayer RGGB, malvar" TRAINING="$(model_log lfnet-asp-n2-bayer-malvar)" \
      record "$tmp" "${src[@]}" --model "$(model_file lfnet-asp-n2-bayer-malvar)" --cfa RGGB
    VARIANT="Bayer RGGB, bilinear" TRAINING="$(model_log lfnet-asp-n2-bayer)" \
      record "$tmp" "${src[@]}" --model "$(model_file lfnet-asp-n2-bayer)" --cfa RGGB
    VARIANT="grey sensor" record "$tmp" "${src[@]}" --model "$(model_file lfnet-asp-n2)"
    for pattern in RGGB GRBG; do
      VARIANT="Bayer $pattern" record "$tmp" "${src[@]}" --method pinv --cfa "$pattern"
    done
    VARIANT="Bayer RGGB, malvar" record "$tmp" "${src[@]}" --method pinv --cfa RGGB \
      --demosaic malvar
    VARIANT="colour" record "$tmp" "${src[@]}" --method no-parallax --cfa RGGB
    VARIANT="grey sensor" record "$tmp" "${src[@]}" --method pinv
    VARIANT="grey" record "$tmp" "${src[@]}" --method no-parallax
  done
  mv "$tmp" results/colour/records.jsonl
}

# Calibration error (docs/acquisition.md, "Calibration error"): on the light fields of the
# cross-scene benchmark, the sensor image of a camera whose ASP is off (modulation depth
# -10 % and +10 %, angular response shifted by 0.1 and 0.25 view, 10 % vignetting, and that
# vignetting divided out by the camera's flat field from its white frame), each reconstruction
# told the nominal Phi: the default trained on the nominal Phi alone against the one trained with
# calibration errors (dataset.calibration), beside pinv and no-parallax.
calibration() {
  local tmp work i error size
  tmp=$(mktemp)
  work=$(mktemp -d)
  need_model "$(model_file lfnet-asp-n2-robust)"
  local vignetting='{"vignetting": 0.1}'
  local errors=('' '{"depth": -0.1}' '{"depth": 0.1}' '{"angular_shift_u": 0.1}'
    '{"angular_shift_u": 0.25}' "$vignetting" flat)
  for ((i = 0; i < ${#heldout[@]}; i += 2)); do
    local src=("${heldout[@]:i:2}" --mode sensor)
    # The vignetted camera's white frame, of the light field's size, for its flat field.
    rm -rf "$work/acq" "$work/white"
    "$lfnet" --log-level warn simulate "${heldout[@]:i:2}" --phi asp:2 --out "$work/acq"
    size=$("$py" -c 'import json, sys; l = json.load(open(sys.argv[1]))["light_field"]
print(str(l["height"]) + "x" + str(l["width"]))' "$work/acq/sensor.json")
    "$lfnet" --log-level warn simulate --white "$size" --phi asp:2 --camera-error "$vignetting" \
      --out "$work/white"
    record "$tmp" --phi asp:2 "${src[@]}" --method no-parallax
    for error in "${errors[@]}"; do
      local camera=()
      if [[ $error == flat ]]; then
        camera=(--camera-error "$vignetting" --flat-field "$work/white")
      elif [[ -n $error ]]; then
        camera=(--camera-error "$error")
      fi
      record "$tmp" --phi asp:2 "${src[@]}" --method pinv "${camera[@]}"
      for name in lfnet-asp-n2 lfnet-asp-n2-robust; do
        VARIANT=$name record "$tmp" --model "$(model_file "$name")" "${src[@]}" --method net \
          "${camera[@]}"
      done
      # The default told the angular shift it estimates from the sensor image itself, and (for
      # the errors a Phi of one period holds) told the camera's error as if measured.
      VARIANT="lfnet-asp-n2, self-calibrated" record "$tmp" --model "$(model_file lfnet-asp-n2)" \
        "${src[@]}" --method net "${camera[@]}" --self-calibrate
      if [[ $error == *depth* || $error == *angular* ]]; then
        VARIANT="lfnet-asp-n2, told" record "$tmp" --model "$(model_file lfnet-asp-n2)" \
          "${src[@]}" --method net "${camera[@]}" --tell-camera-error
      fi
    done
    # With noise of sigma 0.05, not told: the noise switch, with and without self-calibration.
    for error in '' '{"angular_shift_u": 0.1}' '{"angular_shift_u": 0.25}'; do
      local camera=()
      [[ -n $error ]] && camera=(--camera-error "$error")
      for calibrate in '' --self-calibrate; do
        VARIANT="lfnet-asp-n2-auto, estimated${calibrate:+, self-calibrated}" record "$tmp" \
          --model models/lfnet-asp-n2-auto.json "${src[@]}" --method net "${camera[@]}" \
          --noise 0.05 --estimate-noise $calibrate
      done
    done
  done
  mv "$tmp" results/calibration/records.jsonl
  rm -rf "$work"
}

# Learned codes (docs/training.md, "Learned codes"): at N = 2, one lfnet network (32 channels, 3
# levels) and one training budget (out/cache/lfnet-asp-n2-first20.ckpt finetuned for 10 epochs of
# 8,000 crops at lr 5e-4 on the same data) for a fixed code and for a code learned with it: the
# random binary mask (and a hand-designed variant) against a learned mask of its period, the ASP
# quadrature pair against learned ASP gratings (from random gratings, and from the pair), a random
# coded aperture against a learned one; a binary mask learned from the start (straight through its
# rounding); the masks, ASPs and apertures trained with noise (sigma 0 to 0.1) at sigma 0 and
# 0.05, the learned ones also from their noiseless codes, and the pair and the learned ASP so
# trained given 10 noise epochs more (the learned ASP's gratings at code lr 0.01 and at 0.05);
# the shipped default lfnet-asp-n2 and a
# mask learned with its network (4 levels, finetuned from it for 6 epochs, then 14 more); the
# learned mask and ASP given the default's whole training, their codes held (the -full chains), and
# those two ASPs finetuned with noise for 44 epochs (the learned one's code learning on), and the
# mask's -l3 step finetuned with noise for 44 (its code learning on). Each net
# beside pinv of its own camera (pinv-nlm with noise) and no-parallax, on the light fields of the
# cross-scene benchmark, sensor mode. Then the learned codes' pictures (docs/images/learned-codes).
learned-codes() {
  local tmp i m sigma
  local clean=(lfnet-mask-n2 lfnet-mask-n2-s2 lfnet-learned-mask-n2 lfnet-learned-binary-mask-n2
    lfnet-asp-n2-c32-e10 lfnet-learned-asp-n2 lfnet-learned-asp-n2-pair lfnet-aperture-n2
    lfnet-learned-aperture-n2 lfnet-learned-mask-n2-l4 lfnet-learned-mask-n2-l4-e20
    lfnet-learned-mask-n2-full lfnet-learned-mask-n2-full-l3 lfnet-learned-asp-n2-full)
  local noisy=(lfnet-mask-n2-noise lfnet-learned-mask-n2-noise lfnet-learned-mask-n2-noise-from-clean
    lfnet-asp-n2-c32-e10-noise lfnet-learned-asp-n2-noise lfnet-learned-asp-n2-noise-from-clean
    lfnet-asp-n2-full-noise-long lfnet-learned-asp-n2-full-noise-long
    lfnet-learned-mask-n2-full-l3-noise-long lfnet-aperture-n2-noise
    lfnet-learned-aperture-n2-noise-from-clean lfnet-asp-n2-c32-e10-noise-e20
    lfnet-learned-asp-n2-noise-from-clean-e20 lfnet-learned-asp-n2-noise-from-clean-e20-codelr05)
  for m in "${clean[@]}" "${noisy[@]}" lfnet-asp-n2; do need_model "$(model_file "$m")"; done
  tmp=$(mktemp)
  for ((i = 0; i < ${#heldout[@]}; i += 2)); do
    local src=("${heldout[@]:i:2}" --mode sensor)
    record "$tmp" --phi asp:2 "${src[@]}" --method no-parallax
    VARIANT=lfnet-asp-n2 TRAINING="$(model_log lfnet-asp-n2)" record "$tmp" \
      --model "$(model_file lfnet-asp-n2)" "${src[@]}" --method net
    for m in "${clean[@]}"; do
      VARIANT=$m TRAINING="$(model_log "$m")" record "$tmp" --model "$(model_file "$m")" \
        "${src[@]}" --method net
      VARIANT="$m camera" record "$tmp" --model "$(model_file "$m")" "${src[@]}" --method pinv
    done
    for sigma in 0 0.05; do
      for m in "${noisy[@]}"; do
        VARIANT=$m TRAINING="$(model_log "$m")" record "$tmp" --model "$(model_file "$m")" \
          "${src[@]}" --method net --noise "$sigma"
        if [[ $sigma == 0 ]]; then
          VARIANT="$m camera" record "$tmp" --model "$(model_file "$m")" "${src[@]}" --method pinv
          continue
        fi
        VARIANT="$m camera" record "$tmp" --model "$(model_file "$m")" "${src[@]}" --method pinv-nlm \
          --noise "$sigma"
      done
    done
  done
  mv "$tmp" results/learned-codes/records.jsonl
  for m in lfnet-learned-mask-n2 lfnet-learned-binary-mask-n2 lfnet-learned-asp-n2 \
    lfnet-learned-asp-n2-pair lfnet-learned-aperture-n2 lfnet-learned-mask-n2-l4 \
    lfnet-learned-mask-n2-l4-e20 lfnet-learned-mask-n2-noise-from-clean \
    lfnet-learned-mask-n2-full-l3-noise-long lfnet-learned-aperture-n2-noise-from-clean \
    lfnet-learned-asp-n2-noise-from-clean-e20-codelr05; do
    "$lfnet" simulate --phi "$(model_file "$m")" --plot-weights "docs/images/learned-codes/$m" --force
  done
  # The binary mask as a calibrated-Phi folder with its patterns to print (mask_<n>.png).
  "$lfnet" phi export --phi "$(model_file lfnet-learned-binary-mask-n2)" \
    --out docs/images/learned-codes/printable --force
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
      record "$tmp" --model "$(model_file asp-n2)" --lf ../shared/data/hci_antinous \
        --method "$method" --mode sensor --stride "$stride"
    done
  done
  # lfnet's architecture reconstructs the whole sensor image at once: one point, no stride.
  VARIANT=lfnet-asp-n2 record "$tmp" --model "$(model_file lfnet-asp-n2)" \
    --lf ../shared/data/hci_antinous --method net --mode sensor
  mv "$tmp" results/stride-sweep/records.jsonl
}

# The paper's Fig. 4 and section 3.3: each branch alone against the two-branch net, and the
# branches trained separately then jointly (the shipped asp-n2, the same config as
# configs/paper/branch-ablation/pretrained-then-joint.json) against joint training from scratch.
branch-ablation() {
  local tmp lf=(--lf ../shared/data/hci_antinous --mode sensor --stride 5)
  tmp=$(mktemp)
  for method in net ae cnn pinv no-parallax; do
    VARIANT="each branch, then joint" record "$tmp" --model $pq/asp-n2.ckpt "${lf[@]}" --method "$method"
  done
  VARIANT="joint from scratch" record "$tmp" --model $pq/joint-from-scratch.ckpt "${lf[@]}" \
    --method net
  mv "$tmp" results/branch-ablation/records.jsonl
}

# The paper's section 3.2: weighted L2 (the shipped asp-n2, configs/paper/loss-ablation/
# weighted-l2.json) against plain L2.
loss-ablation() {
  local tmp lf=(--lf ../shared/data/hci_antinous --mode sensor --stride 5)
  tmp=$(mktemp)
  VARIANT="weighted L2" record "$tmp" --model $pq/asp-n2.ckpt "${lf[@]}" --method net
  VARIANT="L2" record "$tmp" --model $pq/l2.ckpt "${lf[@]}" --method net
  VARIANT="" record "$tmp" --model $pq/asp-n2.ckpt "${lf[@]}" --method no-parallax
  mv "$tmp" results/loss-ablation/records.jsonl
}

# The paper's section 4: a net trained on three real Lytro light fields, tested on the fourth.
lytro() {
  local tmp pics=out/results/lytro
  tmp=$(mktemp)
  rm -rf "$pics" && mkdir -p "$pics"
  for method in net pinv no-parallax; do
    record "$tmp" --model $pq/lytro.ckpt --lf ../shared/data/lytro_Begonia --mode sensor \
      --stride 5 --method "$method" --out "$pics/$method"
  done
  mv "$tmp" results/lytro/records.jsonl
}

# Phi switching: the ASP model finetuned for a mask (2 epochs) against a mask net trained from
# scratch for as long, and the shipped mask-n2 (the full quick schedule from scratch).
phi-switching() {
  local tmp lf=(--lf ../shared/data/hci_antinous --mode sensor --stride 5)
  tmp=$(mktemp)
  VARIANT="finetuned from asp-n2" TRAINING=$pq/mask-from-asp.training.jsonl \
    record "$tmp" --model $pq/mask-from-asp.ckpt "${lf[@]}" --method net
  VARIANT="from scratch, as long" TRAINING=$pq/mask-from-scratch.training.jsonl \
    record "$tmp" --model $pq/mask-from-scratch.ckpt "${lf[@]}" --method net
  VARIANT="from scratch, ae + cnn + joint" \
    record "$tmp" --model $pq/mask-n2.ckpt "${lf[@]}" --method net
  VARIANT="" record "$tmp" --model $pq/mask-n2.ckpt "${lf[@]}" --method no-parallax
  mv "$tmp" results/phi-switching/records.jsonl
}

# The paper scale of ASP N = 2 (configs/paper/phi-comparison/asp.json --scale paper, 3.8
# hours of this 2-core machine; its model is out/cache/asp-n2-paper.ckpt) beside the quick-scale asp-n2.
paper-scale-asp-n2() {
  local tmp lf=(--lf ../shared/data/hci_antinous --mode sensor)
  tmp=$(mktemp)
  for stride in 9 5; do
    for method in net ae cnn pinv no-parallax; do
      local training=
      [[ $method == net ]] && training="$(model_log asp-n2-paper)"
      VARIANT="paper scale" TRAINING=$training record "$tmp" --model "$(model_file asp-n2-paper)" \
        "${lf[@]}" --stride "$stride" --method "$method"
    done
    VARIANT="quick scale" record "$tmp" --model $pq/asp-n2.ckpt "${lf[@]}" --stride "$stride" \
      --method net
  done
  mv "$tmp" results/paper-scale-asp-n2/records.jsonl
}

# The light fields of the cross-scene benchmark, as pairs of lfnet evaluate arguments.
heldout=(--lf ../shared/data/hci_antinous --lf ../shared/data/lytro_Begonia
         --scene configs/scenes/heldout_window.json --scene configs/scenes/heldout_wide.json)

# The cross-scene benchmark (docs/models.md): ASP N = 2, stride 5, sensor mode, on light fields
# that no model of configs/models/ trained on, from two cameras and a renderer: HCI
# hci_antinous, Lytro Illum lytro_Begonia, the rendered heldout_window (disparities up to
# 2.9 px) and heldout_wide (up to 4 px). Every network of $CROSS_SCENE_MODELS (default: the
# ASP N = 2 models listed below, shipped or made into out/cache/), each named by its path
# under models/ or out/cache/, against no-parallax, pinv and the dictionary; then the bar
# chart of margins over pinv (the section's "margins" figure, drawn by lfnet report).
cross-scene() {
  local tmp models
  local name
  if [[ -n ${CROSS_SCENE_MODELS:-} ]]; then
    read -r -a models <<< "$CROSS_SCENE_MODELS"
  else
    models=()
    for name in asp-n2-paper asp-n2 lfnet-asp-n2-c32 lfnet-asp-n2-c48 lfnet-asp-n2-f10 \
      lfnet-asp-n2-first20 lfnet-asp-n2-l3 lfnet-asp-n2-l4 lfnet-asp-n2-noise lfnet-asp-n2 \
      paper-quick/asp-n2 lfnet-asp-n2-robust lfnet-asp-n2-hard-blend lfnet-asp-n2-c16 \
      lfnet-asp-n2-unrolled; do
      models+=("$(model_file "$name")")
      need_model "${models[-1]}"
    done
  fi
  tmp=$(mktemp)
  local i
  for ((i = 0; i < ${#heldout[@]}; i += 2)); do
    local src=("${heldout[@]:i:2}")
    for method in no-parallax pinv dict; do
      record "$tmp" --model "${models[0]}" --dictionary "$(model_file dictionary)" "${src[@]}" \
        --method "$method" --mode sensor --stride 5
    done
    for model in "${models[@]}"; do
      local name training=
      name=${model#models/}
      name=${name#out/cache/}
      name=${name%.ckpt}
      [[ -f ${model%.ckpt}.training.jsonl ]] && training=${model%.ckpt}.training.jsonl
      VARIANT=$name TRAINING=$training record "$tmp" --model "$model" "${src[@]}" --method net \
        --mode sensor --stride 5
    done
    # The shipped paper-architecture model at stride 2 as well: lfnet's bar.
    VARIANT="asp-n2, stride 2" TRAINING="$(model_log asp-n2)" record "$tmp" \
      --model "$(model_file asp-n2)" "${src[@]}" --method net --mode sensor --stride 2
  done
  mv "$tmp" results/cross-scene/records.jsonl
}

# Adds the networks of $MODELS (paths of checkpoints, space-separated) to the cross-scene
# benchmark as cross-scene measures them, replacing the records of the same variant: a new
# model joins the table without measuring every other one again.
cross-scene-add() {
  local tmp model name training i
  local records=results/cross-scene/records.jsonl
  read -r -a models <<< "${MODELS:?MODELS names the checkpoints to add}"
  tmp=$(mktemp)
  for ((i = 0; i < ${#heldout[@]}; i += 2)); do
    local src=("${heldout[@]:i:2}")
    for model in "${models[@]}"; do
      need_model "$model"
      name=${model#models/}
      name=${name#out/cache/}
      name=${name%.ckpt}
      training=
      [[ -f ${model%.ckpt}.training.jsonl ]] && training=${model%.ckpt}.training.jsonl
      VARIANT=$name TRAINING=$training record "$tmp" --model "$model" "${src[@]}" --method net \
        --mode sensor --stride 5
    done
  done
  replace_variants "$records" "$tmp"
  rm -f "$tmp"
}

# lfnet's shipped ASP model in one pass and as its self-ensemble (--self-ensemble: the four
# mirror images that asp:2 measures as mirrored sensor images, docs/architectures.md), and of
# its first two passes (--ensemble-passes 2: the identity and the left-to-right mirror; also in
# bfloat16), on the light fields of the cross-scene benchmark, beside pinv and no-parallax.
self-ensemble() {
  local tmp i
  tmp=$(mktemp)
  for ((i = 0; i < ${#heldout[@]}; i += 2)); do
    local src=("${heldout[@]:i:2}")
    for method in no-parallax pinv; do
      record "$tmp" --phi asp:2 "${src[@]}" --method "$method" --mode sensor
    done
    VARIANT=lfnet-asp-n2 record "$tmp" --model "$(model_file lfnet-asp-n2)" "${src[@]}" \
      --method net --mode sensor
    VARIANT="lfnet-asp-n2, self-ensemble of 2 passes" record "$tmp" \
      --model "$(model_file lfnet-asp-n2)" "${src[@]}" --method net --mode sensor --self-ensemble \
      --ensemble-passes 2
    VARIANT="lfnet-asp-n2, self-ensemble of 2 passes, bfloat16" record "$tmp" \
      --model "$(model_file lfnet-asp-n2)" "${src[@]}" --method net --mode sensor --self-ensemble \
      --ensemble-passes 2 --precision bfloat16
    VARIANT="lfnet-asp-n2, self-ensemble" record "$tmp" --model "$(model_file lfnet-asp-n2)" \
      "${src[@]}" --method net --mode sensor --self-ensemble
  done
  mv "$tmp" results/self-ensemble/records.jsonl
}

# The shipped models for other cameras on the light fields of the cross-scene benchmark, each
# against pinv and no-parallax of its Phi (stride 5): ASP N = 15 and 25, the coded mask and
# random projections N = 2 of the paper's architecture (configs/models/, quick scale), and
# lfnet's architecture where it has a model (scripts/models.py: ASP N = 15, the mask).
# Random projections are measured per patch (their 9-pixel blocks do not tile a sensor image
# at stride 5), the others in sensor mode.
other-phi() {
  local tmp
  tmp=$(mktemp)
  local i
  for ((i = 0; i < ${#heldout[@]}; i += 2)); do
    local src=("${heldout[@]:i:2}")
    for phi in asp-n15 asp-n25 mask-n2 random-n2; do
      local mode=sensor
      [[ $phi == random-n2 ]] && mode=per_patch
      for method in no-parallax pinv net; do
        local variant=
        [[ $method == net ]] && variant="paper architecture ($phi)"
        VARIANT=$variant TRAINING=$([[ $method == net ]] && echo "$(model_log "$phi")") \
          record "$tmp" --model "$(model_file "$phi")" "${src[@]}" --method "$method" \
          --mode "$mode" --stride 5
      done
      # lfnet's architecture has models for these two cameras only.
      [[ $phi == asp-n15 || $phi == mask-n2 ]] || continue
      need_model "$(model_file "lfnet-$phi")"
      VARIANT="lfnet-$phi" TRAINING="$(model_log "lfnet-$phi")" record "$tmp" \
        --model "$(model_file "lfnet-$phi")" "${src[@]}" --method net --mode sensor --stride 5
    done
  done
  mv "$tmp" results/other-phi/records.jsonl
}

# The paper's own test scene, MIT "Dragons and Bunnies" at its four apertures (3, 4, 5 and
# 6.6 cm; docs/results.md, "The paper's scene"): the paper's Fig. 5 (paper-fig5), Table 1
# (paper-table1), Table 2 (paper-table2), its branch, schedule and loss claims and lfnet's
# models (paper-branches), each section one table over the four apertures. Measured only, never
# trained on or selected by. Resumable: a record whose run (its variant and arguments) is in its
# section already is not measured again, so an interrupted run goes on where it stopped;
# PAPER_SCENE_FRESH=1 starts the four sections anew. PAPER_APERTURES picks apertures.
apertures=(${PAPER_APERTURES:-5 3 4 6.6})

# One evaluation of the paper's scene into section $1 unless its records hold the run already;
# evaluate's arguments follow, $VARIANT labels the record.
scene_record() {
  local section=$1 file key tmp
  shift
  file=results/$section/records.jsonl
  key="${VARIANT:-}|$*"
  if [[ -f $file ]] && KEY=$key "$py" -c '
import json, os, sys
sys.exit(0 if any(json.loads(l).get("run") == os.environ["KEY"]
                  for l in open(sys.argv[1]) if l.strip()) else 1)' "$file"; then
    return 0
  fi
  tmp=$(mktemp)
  "$lfnet" evaluate "$@" --json "$tmp"
  RUN=$key append_record "$file" "$tmp" "${VARIANT:-}"
  rm -f "$tmp"
}

paper-scene() {
  local ap lf method phi n sigma
  if [[ ${PAPER_SCENE_FRESH:-0} == 1 ]]; then
    for s in paper-fig5 paper-table1 paper-branches paper-table2; do
      rm -f results/$s/records.jsonl
    done
  fi
  for m in asp-n2 mask-n2 random-n2 asp-n15 asp-n25 noise-trained noise-trained-0.2 \
    joint-from-scratch l2; do
    need_model "$pq/$m.ckpt"
  done
  need_model "$(model_file asp-n2-paper)"
  need_model "$(model_file lfnet-asp-n2)"
  need_model "$(model_file lfnet-asp-n2-noise)"
  # Fig. 5: the three cameras at N = 2, stride 5, per patch (random projections have no sensor
  # image at stride 5).
  for ap in "${apertures[@]}"; do
    lf=(--lf "../shared/data/mit_dragons_bunnies_5x5_ap$ap")
    for phi in asp mask random; do
      for method in net pinv no-parallax; do
        scene_record paper-fig5 --model "$pq/$phi-n2.ckpt" "${lf[@]}" --method "$method" \
          --mode per_patch --stride 5
      done
    done
  done
  # Table 1: ASP N = 2, 15 and 25 on non-overlapping patches, against the dictionary.
  for ap in "${apertures[@]}"; do
    lf=(--lf "../shared/data/mit_dragons_bunnies_5x5_ap$ap")
    for n in 2 15 25; do
      for method in net dict pinv no-parallax; do
        scene_record paper-table1 --model "$pq/asp-n$n.ckpt" --dictionary "$(model_file dictionary)" \
          "${lf[@]}" --method "$method" --mode sensor --stride 9
      done
    done
  done
  # Fig. 4 and sections 3.2 and 3.3: each branch alone, joint training from scratch, plain L2,
  # the paper scale; lfnet's shipped model beside them. Stride 5, sensor mode.
  for ap in "${apertures[@]}"; do
    lf=(--lf "../shared/data/mit_dragons_bunnies_5x5_ap$ap" --mode sensor)
    for method in net ae cnn pinv no-parallax; do
      VARIANT="quick scale" scene_record paper-branches --model $pq/asp-n2.ckpt "${lf[@]}" \
        --stride 5 --method "$method"
    done
    VARIANT="quick scale, joint from scratch" scene_record paper-branches \
      --model $pq/joint-from-scratch.ckpt "${lf[@]}" --stride 5 --method net
    VARIANT="quick scale, plain L2" scene_record paper-branches --model $pq/l2.ckpt "${lf[@]}" \
      --stride 5 --method net
    for method in net ae cnn; do
      VARIANT="paper scale" scene_record paper-branches --model "$(model_file asp-n2-paper)" \
        "${lf[@]}" --stride 5 --method "$method"
    done
    VARIANT=lfnet-asp-n2 scene_record paper-branches --model "$(model_file lfnet-asp-n2)" \
      "${lf[@]}" --method net
    VARIANT="lfnet-asp-n2, self-ensemble of 2 passes" scene_record paper-branches \
      --model "$(model_file lfnet-asp-n2)" "${lf[@]}" --method net --self-ensemble \
      --ensemble-passes 2
  done
  # Table 2: Gaussian noise 0, 0.1 and 0.2, ASP N = 2, stride 5; the paper's nets trained
  # without noise and at each sigma, the dictionary, and lfnet's models (told the sigma).
  for ap in "${apertures[@]}"; do
    lf=(--lf "../shared/data/mit_dragons_bunnies_5x5_ap$ap" --mode sensor)
    for sigma in 0 0.1 0.2; do
      for method in net dict pinv pinv-nlm no-parallax; do
        local variant=""
        [[ $method == net || $method == dict ]] && variant="trained without noise"
        VARIANT=$variant scene_record paper-table2 --model $pq/asp-n2.ckpt \
          --dictionary "$(model_file dictionary)" "${lf[@]}" --method "$method" --stride 5 \
          --noise "$sigma"
      done
      VARIANT="trained at sigma 0.1" scene_record paper-table2 --model $pq/noise-trained.ckpt \
        "${lf[@]}" --method net --stride 5 --noise "$sigma"
      VARIANT="trained at sigma 0.2" scene_record paper-table2 \
        --model $pq/noise-trained-0.2.ckpt "${lf[@]}" --method net --stride 5 --noise "$sigma"
      VARIANT="lfnet-asp-n2, trained without noise" scene_record paper-table2 \
        --model "$(model_file lfnet-asp-n2)" "${lf[@]}" --method net --noise "$sigma"
      VARIANT="lfnet-asp-n2-noise, noise-aware" scene_record paper-table2 \
        --model "$(model_file lfnet-asp-n2-noise)" "${lf[@]}" --method net --noise "$sigma"
    done
  done
}

# Only the reconstructions behind the pictures of heldout-asp-n2 and lytro (and their viewers,
# index.html), leaving every record as it is: `scripts/results.sh pictures` on a fresh checkout.
pictures() {
  local pics=out/results/heldout-asp-n2 tmp
  tmp=$(mktemp)
  rm -rf "$pics" out/results/lytro && mkdir -p "$pics" out/results/lytro
  for method in net dict pinv no-parallax; do
    "$lfnet" evaluate --model "$(model_file asp-n2)" --dictionary "$(model_file dictionary)" \
      --lf ../shared/data/hci_antinous --method "$method" --mode sensor --stride 5 \
      --json "$tmp" --force --out "$pics/$method"
  done
  for method in net pinv no-parallax; do
    "$lfnet" evaluate --model $pq/lytro.ckpt --lf ../shared/data/lytro_Begonia --mode sensor \
      --stride 5 --method "$method" --json "$tmp" --force --out "out/results/lytro/$method"
  done
  rm -f "$tmp"
}

sections=("$@")
if [[ ${#sections[@]} -eq 0 ]]; then
  sections=(cross-scene self-ensemble other-phi heldout-asp-n2 phi-comparison compression-sweep noise-sweep
            sensor-noise noise-blind calibration colour learned-codes stride-sweep branch-ablation loss-ablation lytro
            phi-switching paper-scene)
fi
for s in "${sections[@]}"; do
  echo "== $s"
  [[ $s == report ]] || "$s"
done
"$lfnet" report results --out docs/RESULTS.md
