#!/usr/bin/env bash
# Installs every Debian package lfnet needs. Idempotent: does nothing when all are present.
set -euo pipefail

# libopencv-dev: its core and photo modules are linked by lfnet's cv library (OpenCV's
# non-local means for pinv-nlm), outside the numerical core. iproute2: the two-host test's
# network namespaces (tests/dist/two_hosts.sh).
packages=(
  build-essential cmake ninja-build pkg-config clang-format clang-tidy
  libtorch-dev libopenblas0-openmp libgloo-dev
  libopencv-dev libopenimageio-dev openimageio-tools
  nlohmann-json3-dev libspdlog-dev libfmt-dev catch2 libcli11-dev zlib1g-dev libdeflate-dev
  python3 python3-numpy python3-skimage python3-sklearn python3-torch python3-imageio
  python3-matplotlib python3-pil
  chromium
  iproute2
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

echo "install-deps: installing ${missing[*]}"
sudo_cmd=()
[ "$(id -u)" -ne 0 ] && sudo_cmd=(sudo)
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -q
"${sudo_cmd[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}"

# LibTorch falls back to the reference BLAS unless OpenBLAS (OpenMP) is the selected alternative.
for alt in libblas.so.3-x86_64-linux-gnu liblapack.so.3-x86_64-linux-gnu; do
  target=$(update-alternatives --list "$alt" 2>/dev/null | grep openblas-openmp | head -n1 || true)
  [ -n "$target" ] && "${sudo_cmd[@]}" update-alternatives --set "$alt" "$target" >/dev/null
done
echo "install-deps: done"
