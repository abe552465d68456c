#!/usr/bin/env bash
# The main job on the embedded default: installs dependencies, builds, renders the synthetic `demo`
# dataset (a procedural street drive, two laps, the second at dusk), prints its summary, then runs the
# full-DIRD detector over it and prints the run's summary (loops found, how many within 2 m of truth).
# Usage: scripts/demo.sh [OUT_DIR]   (default: out/demo; the run's outputs go to OUT_DIR-run)
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
run_out="$out-run"
rm -rf "$run_out"
build/release/loopgate run --config configs/demo.yaml --dataset "$out" --out "$run_out" --mode full
/usr/bin/python3 - "$run_out/summary.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
t = s.get("loop_truth", {})
print(f"demo: {s['frames_processed']} frames, {s.get('loops', 0)} loop closures "
      f"({t.get('loops_within_accept_radius', 0)} within {t.get('accept_radius_m', 0)} m of ground truth, "
      f"{t.get('loops_beyond_accept_radius', 0)} beyond); best detection of {t.get('query_frames_with_loops', 0)} "
      f"query frames: {t.get('query_best_loop_within_accept_radius', 0)} true; wall {s['wall_s']:.2f} s")
PY
echo "demo: run outputs (frames.csv, loops.csv, timing.csv, summary.json) in $run_out" >&2
