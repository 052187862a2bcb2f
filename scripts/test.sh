#!/usr/bin/env bash
# Installs what is missing, builds, runs every test, then checks formatting and lint
# (scripts/lint.sh: clang-format on every C++ file, clang-tidy on the sources changed by the
# last commit). Usage: scripts/test.sh [ctest args]
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
scripts/install-deps.sh
scripts/build.sh
built=$(date +%s)
tests=0
(cd build && ctest --output-on-failure --timeout 1500 -j"$(nproc)" "$@") || tests=$?
tested=$(date +%s)
lint=0
scripts/lint.sh || lint=$?
end=$(date +%s)
echo "test.sh: install+build $((built - start)) s, tests $((tested - built)) s, lint $((end - tested)) s"
[[ $tests -eq 0 && $lint -eq 0 ]]
