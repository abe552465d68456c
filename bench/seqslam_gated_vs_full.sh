#!/bin/sh
# Full SeqSLAM vs gated SeqSLAM, each run N times (default 3, alternating, each alone) by
# `loopgate run --method seqslam --mode full|gated` on one dataset; prints every run's times and the medians:
#   wall        the whole run's wall time (decode, odometry, gate, describe, match, sink, end of stream)
#   end         the end-of-stream time (SeqSLAM's difference matrix, contrast enhancement and search)
#   detection   describe + match of the time accounting (thread CPU time, summary.json "time_accounting":
#               describe = SeqSLAM's preprocessing without the image reads, match = match + the end-of-stream
#               search)
#   +decode     the same plus decode (the decode stage and every image read inside describe, wherever read)
#   cpu         process CPU time
# then the work and the accuracy of the last run of each (they do not vary): frames preprocessed
# (descriptors_computed), difference-matrix entries computed (similarities_computed), loops true / false, AP,
# recall at 100% precision, and for gated the gate's coverage of the true-loop query frames.
# Usage: bench/seqslam_gated_vs_full.sh CONFIG [DATASET] [N] [BUILD_DIR]
#   e.g. bench/seqslam_gated_vs_full.sh configs/kitti00-thumbs.yaml ../shared/data/kitti/00/thumbs 3
set -eu
here=$(cd "$(dirname "$0")/.." && pwd)
config=${1:?usage: bench/seqslam_gated_vs_full.sh CONFIG [DATASET] [N] [BUILD_DIR]}
dataset=${2:-}
n=${3:-3}
build=${4:-$here/build/release}
[ -x "$build/loopgate" ] || { echo "no loopgate binary in $build (build it first)" >&2; exit 1; }
out=$(mktemp -d /tmp/loopgate-seqslam-gated-vs-full.XXXXXX)
i=1
while [ "$i" -le "$n" ]; do
  for mode in full gated; do
    if [ -n "$dataset" ]; then
      "$build/loopgate" --log-level warn run --config "$config" --dataset "$dataset" --method seqslam \
        --mode "$mode" --out "$out/$mode-$i" --set output.progress=off >"$out/$mode-$i.log" 2>&1
    else
      "$build/loopgate" --log-level warn run --config "$config" --method seqslam \
        --mode "$mode" --out "$out/$mode-$i" --set output.progress=off >"$out/$mode-$i.log" 2>&1
    fi
  done
  i=$((i + 1))
done
/usr/bin/python3 - "$out" "$n" <<'PY'
import json, statistics, sys
out, n = sys.argv[1], int(sys.argv[2])


def times(s):
    t = s["time_accounting"]
    detection = t["describe_ms"] + t["match_ms"]
    return {"wall": 1000 * s["wall_s"], "end": s.get("end_of_stream_ms", 0.0), "detection": detection,
            "+decode": detection + t["decode_ms"], "cpu": 1000 * s["cpu_s"]}


runs = {m: [json.load(open(f"{out}/{m}-{i}/summary.json")) for i in range(1, n + 1)] for m in ("full", "gated")}
for m, summaries in runs.items():
    for i, s in enumerate(summaries, 1):
        print(f"{m} run {i}: " + ", ".join(f"{k} {v:.1f} ms" for k, v in times(s).items()))
med = {m: {k: statistics.median(times(s)[k] for s in summaries) for k in times(summaries[0])}
       for m, summaries in runs.items()}
for m in runs:
    print(f"{m} median of {n}: " + ", ".join(f"{k} {v:.1f} ms" for k, v in med[m].items()))
print("full / gated (medians): " + ", ".join(
    f"{k} {med['full'][k] / med['gated'][k]:.2f}x" for k in med["full"] if med["gated"][k] > 0))
for m, summaries in runs.items():
    s = summaries[-1]
    e = s.get("evaluation", {})
    pr, lt = e.get("precision_recall", {}), e.get("loop_truth", {})
    line = (f"{m}: frames preprocessed {s['descriptors_computed']}, difference entries {s['similarities_computed']}, "
            f"peak RSS {s['peak_rss_mb']:.0f} MiB, loops true/false {lt.get('loops_true')}/{lt.get('loops_false')}, "
            f"AP {pr.get('average_precision', float('nan')):.3f}, R@P100 {pr.get('recall_at_100', float('nan')):.3f}")
    cov = e.get("gate_coverage")
    if cov:
        line += f", true-loop query frames in areas {cov['covered_query_frames']} of {cov['positive_query_frames']}"
    if "seqslam_gated" in s:
        g = s["seqslam_gated"]
        line += (f"; frames of cells {g['frames_of_cells']} + neighbours only {g['frames_neighbours_only']}, "
                 f"queries searched {g['queries_searched']}, minimum subtracted {g['minimum_subtracted']:.4f}")
    print(line)
print(f"outputs in {out}")
PY
