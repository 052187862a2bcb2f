#!/bin/bash
# A newcomer's wait: a fresh clone of this checkout's HEAD (../shared linked beside it, the
# packages installed, no compiler cache) builds the program as scripts/run.sh does and starts
# the quickstart experiment; prints, per build setting, the build steps and seconds and the
# seconds from the start to the first training epoch's progress bar, then stops the run
# (docs/building.md). Each setting is given as CMake arguments; the default compares the unity
# build (the default) with one file per translation unit:
#   scripts/build-time.sh                     # -DLFNET_UNITY_BUILD=ON, then OFF
#   VARIANTS="-DLFNET_UNITY_BUILD=ON" scripts/build-time.sh
# Run it on an otherwise quiet machine: it measures wall time.
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$(pwd)
shared=$(realpath ../shared)
IFS=';' read -r -a variants <<< "${VARIANTS:--DLFNET_UNITY_BUILD=ON;-DLFNET_UNITY_BUILD=OFF}"
for variant in "${variants[@]}"; do
  work=$(mktemp -d)
  git clone -q "$repo" "$work/main"
  ln -s "$shared" "$work/shared"
  (
    cd "$work/main"
    start=$(date +%s.%N)
    # shellcheck disable=SC2086
    LFNET_TARGET=lfnet CCACHE_DISABLE=1 scripts/build.sh $variant > build.log 2>&1
    built=$(date +%s.%N)
    steps=$(grep -c '^\[[0-9]*/[0-9]*\]' build.log || true)
    /usr/bin/python3 - "$start" "$built" "$steps" "$variant" <<'PY'
import subprocess, sys, time
start, built, steps, variant = float(sys.argv[1]), float(sys.argv[2]), sys.argv[3], sys.argv[4]
p = subprocess.Popen(["build/apps/lfnet", "experiment", "configs/quickstart.json", "--out",
                      "out/quickstart", "--force"], stdout=subprocess.DEVNULL,
                     stderr=subprocess.PIPE)
seen = b""
while True:
    chunk = p.stderr.read1(4096)
    if not chunk:
        sys.exit("build-time.sh: the experiment ended before its first epoch")
    seen = (seen + chunk)[-256:]
    if b"epoch 1/" in seen:
        break
first = time.time()
p.kill()
p.wait()
print(f"{variant}\tbuild steps {steps}\tbuild {built - start:.0f} s\t"
      f"first epoch after {first - start:.0f} s ({(first - start) / 60:.1f} min)", flush=True)
PY
  )
  rm -rf "$work"
done
