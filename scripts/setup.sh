#!/usr/bin/env bash
# Installs loopgate's build and run dependencies from Debian packages. Idempotent: installs only
# what is missing, and runs apt-get update only when something is. librosbag-storage-dev and
# libsensor-msgs-dev are for ROS1 bag input (CMake option LOOPGATE_WITH_ROSBAG, on when they are found).
set -euo pipefail
packages=(
  cmake ninja-build g++ pkg-config libdeflate-dev
  libeigen3-dev libopencv-dev libtbb-dev libspdlog-dev libcli11-dev libnanoflann-dev
  libyaml-cpp-dev nlohmann-json3-dev libgtest-dev libgmock-dev libbenchmark-dev
  libceres-dev
  librosbag-storage-dev libsensor-msgs-dev
  python3-matplotlib python3-numpy
  parallel
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}" >&2
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
