#!/usr/bin/env bash
# The main job on the embedded default: installs dependencies, builds, renders the synthetic `demo`
# dataset if it is absent (a street drive: a block by day, new streets with an aliased copy of it, the block
# again at night under street lamps and headlights), then runs `loopgate compare` on it: every method, full
# and gated (DIRD, the paper's method; SeqSLAM; standardised DIRD; dird-seqslam) side by side, printing one
# table (time per stage, descriptors, loops true/false, PR figures) and writing the plots.
# Usage: scripts/demo.sh [OUT_DIR]   (default: out/demo; the comparison goes to OUT_DIR-compare)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/demo}
scripts/setup.sh
scripts/build.sh release loopgate  # the tool only: the tests are built by scripts/test.sh
if [ -f "$out/simulation.json" ]; then
  echo "demo: $out already rendered (delete it to render again)" >&2
else
  rm -rf "$out"
  build/release/loopgate simulate --preset demo --out "$out"
fi
echo "demo: dataset in $out (EuRoC layout: $out/mav0), metadata in $out/simulation.json" >&2
compare_out="$out-compare"
rm -rf "$compare_out"
build/release/loopgate compare --config configs/demo.yaml --dataset "$out" --out "$compare_out" \
  --set output.progress=off
echo "demo: open $compare_out/plots/*.png (pr.png, plane.png, trajectory.png, time_per_frame.png);" \
  "per-run outputs in $compare_out/<method>/" >&2
