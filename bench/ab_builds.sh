#!/bin/sh
# Two builds of loopgate on the same run: `loopgate run --rate max` N times each (default 5), A and B
# alternating so that a change of the machine's speed hits both; prints every run's real-time factor, CPU
# seconds and end of the stream, then the medians and the ratio B / A. Real-time factors from different times
# do not compare (docs/results.md); the ratio of one such measurement does.
# Usage: bench/ab_builds.sh LOOPGATE_A LOOPGATE_B CONFIG DATASET [N] [--set KEY=VALUE ...]
#   e.g. bench/ab_builds.sh old/loopgate build/release/loopgate configs/euroc-mh05.yaml /work/data/mh05 5 \
#          --set odometry.source=ekf
set -eu
usage="usage: bench/ab_builds.sh LOOPGATE_A LOOPGATE_B CONFIG DATASET [N] [--set KEY=VALUE ...]"
binary_a=${1:?$usage}
binary_b=${2:?$usage}
config=${3:?$usage}
dataset=${4:?$usage}
n=5
shift 4
case "${1:-}" in '' | -*) ;; *) n=$1 && shift ;; esac
for binary in "$binary_a" "$binary_b"; do
  [ -x "$binary" ] || { echo "ab_builds.sh: $binary is not an executable loopgate" >&2; exit 2; }
done
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
median() { sort -g | awk '{v[NR] = $1} END {print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2}'; }
# summary.json's field NAME (a number at the top level) of run directory DIR.
field() { grep -o "\"$2\": *[0-9.e+-]*" "$1/summary.json" | head -1 | sed 's/.*: *//'; }
for k in $(seq 1 "$n"); do
  for side in A B; do
    binary=$binary_a
    [ "$side" = B ] && binary=$binary_b
    rm -rf "$out/run"
    if ! "$binary" run --config "$config" --dataset "$dataset" --rate max --set output.progress=off "$@" \
      --out "$out/run" >"$out/log" 2>&1; then
      echo "ab_builds.sh: run $k ($side: $binary) failed:" >&2
      grep -E '\[(error|critical)\]' "$out/log" >&2 || tail -5 "$out/log" >&2
      exit 1
    fi
    rtf=$(field "$out/run" realtime_factor)
    printf 'run %s %s: real-time factor %.2f, cpu %.2f s, end of stream %.0f ms (load %s)\n' "$k" "$side" \
      "$rtf" "$(field "$out/run" cpu_s)" "$(field "$out/run" end_of_stream_ms)" "$(cut -d' ' -f1 /proc/loadavg)"
    echo "$rtf" >>"$out/$side"
  done
done
a=$(median <"$out/A")
b=$(median <"$out/B")
awk -v n="$n" -v a="$a" -v b="$b" 'BEGIN {printf "median of %d: A %.2fx, B %.2fx, B / A %.3f\n", n, a, b, b / a}'
