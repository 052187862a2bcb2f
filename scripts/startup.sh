#!/bin/bash
# What starting lfnet costs (docs/performance.md, "Start-up"): the median and fastest wall
# seconds of RUNS (default 11) starts each of
#   lfnet --version       the launcher alone (apps/lfnet/launcher.cc)
#   lfnet-run --version   the program holding the commands: every library loaded and initialised
#   libtorch-only         an empty main linked to LibTorch's CPU library (built here)
#   libc-only             an empty main
# then how many shared libraries each loads, and the dynamic loader's count of lfnet-run's start
# (LD_DEBUG=statistics: cycles in the loader, the share spent relocating).
# Usage: scripts/startup.sh [BUILD_DIR]   (RUNS=21 scripts/startup.sh)
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
runs=${RUNS:-11}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
echo 'int main() { return 0; }' > "$work/empty.cc"
g++ -O2 "$work/empty.cc" -o "$work/libc-only"
g++ -O2 "$work/empty.cc" -o "$work/libtorch-only" -Wl,--no-as-needed -ltorch_cpu -lc10
/usr/bin/python3 - "$runs" "$build/apps/lfnet --version" "$build/apps/lfnet-run --version" \
  "$work/libtorch-only" "$work/libc-only" <<'PY'
import statistics, subprocess, sys, time
runs = int(sys.argv[1])
print("program\tmedian_s\tfastest_s")
for command in sys.argv[2:]:
    seconds = []
    for _ in range(runs):
        start = time.perf_counter()
        subprocess.run(command.split(), stdout=subprocess.DEVNULL, check=True)
        seconds.append(time.perf_counter() - start)
    name = " ".join(part.rsplit("/", 1)[-1] for part in command.split())
    print("%s\t%.3f\t%.3f" % (name, statistics.median(seconds), min(seconds)))
PY
echo "shared libraries: lfnet $(ldd "$build/apps/lfnet" | wc -l)," \
  "lfnet-run $(ldd "$build/apps/lfnet-run" | wc -l), libtorch-only $(ldd "$work/libtorch-only" | wc -l)"
LD_DEBUG=statistics "$build/apps/lfnet-run" --version 2>&1 >/dev/null |
  grep -E "total startup time|time needed for relocation|number of relocations:" |
  sed 's/^ *[0-9]*: *//' | sort -u
