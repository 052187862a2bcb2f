#!/usr/bin/env bash
# Fuzzes the config parser, the light-field folder loader, the sensor-image loaders and model
# file reading with libFuzzer (docs/robustness.md).
#
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]     (default: 300 s; every target)
#
# Builds into build-fuzz/ (never into build/): the fuzz targets, and the lfnet sources they
# exercise most (JSON reading, Phi specs, the experiment config, image and folder reading),
# with clang's -fsanitize=fuzzer,address; the rest of lfnet is linked from the static
# libraries of the Release build in build/ (built here if missing). Each run starts from
# tests/fuzz/corpus/<target> and leaves new inputs in build-fuzz/corpus/<target>; crashes land
# in build-fuzz/crashes/<target>. Copy a fixed crash into tests/fuzz/regressions/<target> so
# the normal build replays it (ctest -R fuzz_).
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-300}"
shift || true
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(config light_field_folder acquisition checkpoint)

if ! command -v clang++ >/dev/null || ! ls /usr/lib/llvm-*/lib/clang/*/lib/linux/libclang_rt.fuzzer-x86_64.a >/dev/null 2>&1; then
  echo "installing clang (libFuzzer)" >&2
  apt-get install -y clang
fi

# The uninstrumented rest of lfnet.
# (LFNET_FUZZ_NO_BUILD=1 skips this while another build runs in build/.)
if [ -z "${LFNET_FUZZ_NO_BUILD:-}" ]; then
  [ -f build/CMakeCache.txt ] || scripts/build.sh
  ninja -C build lfnet_core lfnet_optics lfnet_scene lfnet_nn lfnet_dict lfnet_recon lfnet_train \
    lfnet_data lfnet_eval lfnet_io lfnet_pipeline >/dev/null
fi

out=build-fuzz
mkdir -p "$out/obj"
cxx=(clang++ -std=c++17 -g -O1 -fno-omit-frame-pointer -fsanitize=fuzzer-no-link,address
     -D_GLIBCXX_USE_CXX11_ABI=1 -DFMT_SHARED -DSPDLOG_COMPILED_LIB -DSPDLOG_FMT_EXTERNAL
     -DSPDLOG_SHARED_LIB -Ilfnet/include -isystem /usr/include/torch/csrc/api/include
     -Wno-unused-command-line-argument)

compile() {  # source -> object, rebuilt when the source or any lfnet header is newer
  local src="$1" obj="$out/obj/$(echo "$1" | tr / _).o"
  if [ ! -f "$obj" ] || [ "$src" -nt "$obj" ] || [ -n "$(find lfnet/include -newer "$obj" -print -quit)" ]; then
    echo "compiling $src" >&2
    "${cxx[@]}" -c "$src" -o "$obj"
  fi
  echo "$obj"
}

libs=(-Wl,--start-group build/lfnet/src/*/liblfnet_*.a -Wl,--end-group
      -ltorch -ltorch_cpu -lc10 -lOpenImageIO -lOpenImageIO_Util -lspdlog -lfmt -lz -lpthread)

declare -A instrumented=(
  [config]="lfnet/src/pipeline/experiment.cc lfnet/src/pipeline/sources.cc lfnet/src/core/json.cc lfnet/src/optics/phi.cc lfnet/src/optics/asp.cc lfnet/src/optics/local_models.cc"
  [light_field_folder]="lfnet/src/io/light_field_io.cc lfnet/src/io/sensor_io.cc lfnet/src/core/json.cc"
  [acquisition]="lfnet/src/io/sensor_io.cc lfnet/src/io/phi_io.cc lfnet/src/core/json.cc lfnet/src/optics/local_models.cc"
  [checkpoint]="lfnet/src/pipeline/models.cc lfnet/src/train/checkpoint.cc lfnet/src/dict/dictionary.cc lfnet/src/nn/script.cc"
)

for t in "${targets[@]}"; do
  objs=("$(compile "tests/fuzz/fuzz_$t.cc")")
  for src in ${instrumented[$t]}; do objs+=("$(compile "$src")"); done
  bin="$out/fuzz_$t"
  if [ ! -f "$bin" ] || [ -n "$(find "${objs[@]}" -newer "$bin")" ]; then
    echo "linking $bin" >&2
    clang++ -fsanitize=fuzzer,address "${objs[@]}" "${libs[@]}" -o "$bin"
  fi
  mkdir -p "$out/corpus/$t" "$out/crashes/$t"
  echo "fuzzing $t for $seconds s" >&2
  # One worker on this 2-core machine; a 4 GB RSS and malloc ceiling (an image header may
  # legitimately ask for a large buffer); 10 s per input counts as a hang.
  ASAN_OPTIONS=detect_leaks=0 "$bin" -max_total_time="$seconds" -rss_limit_mb=4096 \
    -malloc_limit_mb=4096 -timeout=10 -print_final_stats=1 \
    -artifact_prefix="$out/crashes/$t/" "$out/corpus/$t" "tests/fuzz/corpus/$t" \
    2>&1 | tee "$out/fuzz_$t.log" | grep -E "^#[0-9]+ *(DONE|pulse)|stat::|ERROR|SUMMARY|Test unit written" || true
done
