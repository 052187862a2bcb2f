#!/usr/bin/env bash
# Installs what is missing, builds, and runs the main job on built-in default data.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
scripts/build.sh
out=${1:-out/quickstart}
if [ -d ../shared/data/hci_antinous ]; then
  build/apps/lfnet info --lf ../shared/data/hci_antinous
fi
