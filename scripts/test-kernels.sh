#!/usr/bin/env bash
# Runs the whole test suite once per OpenBLAS kernel and thread count, to find results that
# depend on how BLAS rounds (docs/robustness.md, section 3). Usage: scripts/test-kernels.sh
# [ctest args]. Kernels: the one OpenBLAS picks, Haswell, and SkylakeX where the CPU has
# AVX-512; threads: 1 and 2 (OMP_NUM_THREADS: the tests' LibTorch, and lfnet's default).
# Prints one line per setting and exits non-zero if any setting failed.
set -uo pipefail
cd "$(dirname "$0")/.."
scripts/build.sh >/dev/null || exit 1
kernels=(default Haswell)
grep -qw avx512f /proc/cpuinfo && kernels+=(SkylakeX)
status=0
for kernel in "${kernels[@]}"; do
  for threads in 1 2; do
    log="build/test-kernels-${kernel}-${threads}.log"
    env=(OMP_NUM_THREADS="$threads")
    [ "$kernel" != default ] && env+=(OPENBLAS_CORETYPE="$kernel")
    start=$(date +%s)
    (cd build && env "${env[@]}" ctest --timeout 1500 -j"$(nproc)" "$@") >"$log" 2>&1
    rc=$?
    result=$(grep -E "tests passed|tests failed" "$log" | tail -n1)
    line="kernel ${kernel}, ${threads} thread(s): ${result:-no result} ($(( $(date +%s) - start )) s, log $log)"
    echo "$line"
    if [ $rc -ne 0 ]; then
      status=1
      grep -E "^\s+[0-9]+ - " "$log" | sed 's/^/    failed: /'
    fi
  done
done
exit $status
