#!/bin/sh
# Peak resident memory of a full-mode run (DIRD on every frame, all pairs beyond the margin) over KITTI 00's
# 4540 thumbnails: descriptors are 3456 bytes per frame (15.7 MB for the run); everything else per frame
# is bounded (the matcher keeps the last L-1 DP columns and ~3W+1 columns of kept entries).
# Usage: bench/full_run_memory.sh [BUILD_DIR (default build/release)] [DATASET] [OUT_DIR]
set -eu
here=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$here/build/release}
dataset=${2:-$here/../shared/data/kitti/00/thumbs}
out=${3:-$(mktemp -d /tmp/loopgate-full-memory.XXXXXX)}
[ -x "$build/loopgate" ] || { echo "no loopgate binary in $build (build it first)" >&2; exit 1; }
[ -d "$dataset" ] || { echo "dataset $dataset not found" >&2; exit 1; }
log="$out/time.log"
/usr/bin/time -v "$build/loopgate" run --config "$here/configs/kitti00-thumbs.yaml" --mode full \
  --dataset "$dataset" --out "$out" --set output.progress=off >"$out/run.log" 2>"$log"
frames=$(/usr/bin/python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['frames_processed'])" "$out/summary.json")
rss_kb=$(sed -n 's/.*Maximum resident set size (kbytes): *//p' "$log")
wall=$(sed -n 's/.*Elapsed (wall clock) time (h:mm:ss or m:ss): *//p' "$log")
echo "full run: $frames frames, peak RSS $rss_kb KiB ($(( rss_kb / 1024 )) MiB), wall $wall;" \
  "descriptors $(( frames * 3456 / 1024 )) KiB; outputs in $out"
