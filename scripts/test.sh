#!/usr/bin/env bash
# Installs what is missing, builds, and runs every test. Usage: scripts/test.sh [ctest args]
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
scripts/install-deps.sh
scripts/build.sh
built=$(date +%s)
cd build
ctest --output-on-failure --timeout 1500 -j"$(nproc)" "$@"
end=$(date +%s)
echo "test.sh: install+build $((built - start)) s, tests $((end - built)) s"
