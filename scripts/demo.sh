#!/usr/bin/env bash
# The main job on the embedded default: installs dependencies, builds, renders the synthetic `demo`
# dataset (a procedural street drive, two laps under different light) and prints its summary.
# Usage: scripts/demo.sh [OUT_DIR]   (default: out/demo)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/demo}
scripts/setup.sh
scripts/build.sh release
if [ -f "$out/simulation.json" ]; then
  echo "demo: $out already rendered (delete it to render again)" >&2
else
  rm -rf "$out"
  build/release/loopgate simulate --preset demo --out "$out"
fi
echo "demo: dataset in $out (EuRoC layout: $out/mav0), metadata in $out/simulation.json" >&2
