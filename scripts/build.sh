#!/usr/bin/env bash
# Configures and builds lfnet into build/ (Release). Extra arguments go to CMake. With
# LFNET_TARGET set (e.g. lfnet), builds only that target: scripts/run.sh needs the program, not
# the tests. A compiler cache (ccache) is used when one is installed.
set -euo pipefail
cd "$(dirname "$0")/.."
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
if [ ! -f build/CMakeCache.txt ]; then
  cmake -S . -B build "${generator[@]}" "${launcher[@]}" -DCMAKE_BUILD_TYPE=Release "$@"
fi
target=()
[ -n "${LFNET_TARGET:-}" ] && target=(--target "$LFNET_TARGET")
cmake --build build --parallel "$(nproc)" "${target[@]}"
