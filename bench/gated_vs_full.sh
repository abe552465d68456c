#!/bin/sh
# Full DIRD vs gated DIRD, measured side by side by `loopgate compare` N times (default 5) on one dataset; prints
# every run's figures and the medians of the ratios full / gated of the time accounting's parts (thread CPU time,
# summary.json "time_accounting"; docs/architecture.md § Time accounting):
#   decode         the decode stage plus every image read inside describe (a gated re-read is a decode)
#   describe       descriptors (SeqSLAM: preprocessing), without the reads
#   match          similarities, sequence DP + NMS, the end-of-stream search
#   desc+match     describe + match: what the paper's 6.45x (KITTI 00, Fig. 8) compares with
#   +decode        decode + describe + match
#   total          decode + describe + match + rest (sync, odometry, gate, sink, loop closure)
#   wall           the whole run's wall time
#   descriptors    descriptors computed
# and the share of true-loop query frames inside candidate areas.
# Usage: bench/gated_vs_full.sh CONFIG [DATASET] [N] [BUILD_DIR]
#   e.g. bench/gated_vs_full.sh configs/kitti00-thumbs.yaml ../shared/data/kitti/00/thumbs 5
set -eu
here=$(cd "$(dirname "$0")/.." && pwd)
config=${1:?usage: bench/gated_vs_full.sh CONFIG [DATASET] [N] [BUILD_DIR]}
dataset=${2:-}
n=${3:-5}
build=${4:-$here/build/release}
[ -x "$build/loopgate" ] || { echo "no loopgate binary in $build (build it first)" >&2; exit 1; }
out=$(mktemp -d /tmp/loopgate-gated-vs-full.XXXXXX)
i=1
while [ "$i" -le "$n" ]; do
  if [ -n "$dataset" ]; then
    "$build/loopgate" --log-level warn compare --config "$config" --dataset "$dataset" --methods full,gated \
      --no-plots --out "$out/$i" --set output.progress=off >"$out/$i.log" 2>&1
  else
    "$build/loopgate" --log-level warn compare --config "$config" --methods full,gated \
      --no-plots --out "$out/$i" --set output.progress=off >"$out/$i.log" 2>&1
  fi
  i=$((i + 1))
done
/usr/bin/python3 - "$out" "$n" <<'PY'
import json, statistics, sys
out, n = sys.argv[1], int(sys.argv[2])
keys = [("decode", "full_over_gated_decode_time"), ("describe", "full_over_gated_describe_time"),
        ("match", "full_over_gated_match_time"), ("desc+match", "full_over_gated_describe_and_match_time"),
        ("+decode", "full_over_gated_decode_describe_and_match_time"), ("total", "full_over_gated_total_time"),
        ("wall", "full_over_gated_wall_time"), ("descriptors", "full_over_gated_descriptors")]
rows = []
for i in range(1, n + 1):
    c = json.load(open(f"{out}/{i}/compare.json"))
    f, g, r = c["full"], c["gated"], c["comparison"]
    rows.append(r)
    print(f"run {i}: full wall {f['wall_s']:.3f} s, gated wall {g['wall_s']:.3f} s; " +
          ", ".join(f"{name} {r[key]:.2f}x" for name, key in keys))
print(f"median of {n}: " + ", ".join(f"{name} {statistics.median(r[key] for r in rows):.2f}x" for name, key in keys))
cov = rows[0].get("gated_true_loop_frames_in_candidate_areas")
if cov is not None:
    print(f"true-loop query frames inside candidate areas: {100 * cov:.1f}%")
print(f"descriptors: full {c['full']['descriptors_computed']}, gated {c['gated']['descriptors_computed']}; "
      f"similarities: full {c['full']['similarities_computed']}, gated {c['gated']['similarities_computed']}")
print(f"outputs in {out}")
PY
