#!/bin/sh
# What loop closure (verification + pose graph) costs a whole run: `loopgate run --rate max` N times (default 5)
# with the config as it is and with verify.enabled=false posegraph.enabled=false, the two interleaved so that a
# change of the machine's speed hits both; prints every run's real-time factor and the medians and their ratio.
# Real-time factors from different days do not compare (docs/results.md); the ratio does.
# Usage: bench/verify_cost.sh CONFIG DATASET [N] [BUILD_DIR] [--set KEY=VALUE ...]
#   e.g. bench/verify_cost.sh configs/euroc-mh05.yaml /work/data/mh05 5 build/release --set odometry.source=ekf
set -eu
here=$(cd "$(dirname "$0")/.." && pwd)
usage="usage: bench/verify_cost.sh CONFIG DATASET [N] [BUILD_DIR] [--set KEY=VALUE ...]"
config=${1:?$usage}
dataset=${2:?$usage}
n=${3:-5}
build=${4:-$here/build/release}
shift $(($# < 4 ? $# : 4))
binary=$build/loopgate
[ -x "$binary" ] || { echo "verify_cost.sh: no loopgate at $binary (build first)" >&2; exit 2; }
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
median() { sort -g | awk '{v[NR] = $1} END {print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2}'; }
for k in $(seq 1 "$n"); do
  for variant in with without; do
    extra=""
    [ "$variant" = without ] && extra="--set verify.enabled=false --set posegraph.enabled=false"
    rm -rf "$out/run"
    # shellcheck disable=SC2086
    if ! "$binary" run --config "$config" --dataset "$dataset" --rate max --set output.progress=off "$@" $extra \
      --out "$out/run" >"$out/log" 2>&1; then
      echo "verify_cost.sh: run $k ($variant) failed:" >&2
      tail -5 "$out/log" >&2
      exit 1
    fi
    rtf=$(grep -o 'real-time factor [0-9.]*' "$out/log" | tail -1 | awk '{print $3}')
    echo "run $k $variant loop closure: real-time factor $rtf (load $(cut -d' ' -f1 /proc/loadavg))"
    echo "$rtf" >>"$out/$variant"
  done
done
with=$(median <"$out/with")
without=$(median <"$out/without")
echo "median of $n: ${with}x with loop closure, ${without}x without, ratio $(awk -v a="$with" -v b="$without" 'BEGIN {printf "%.2f", a / b}')"
