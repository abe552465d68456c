#!/usr/bin/python3
"""How far apart, by the ground truth, are the two views of each loop the run's geometric verification tried
(loop_edges.csv, skipped loops left out): the distance between the positions of frames i and j and the angle
between their orientations, per loop and as ranges per outcome. An outcome is "verified", "rejected, tracking
fallback tried" (the reason holds "tracked:") or "rejected".

Reads RUN_DIR/loop_edges.csv, RUN_DIR/frames.csv (frame -> t_s) and RUN_DIR/ground_truth.tum (a run writes
it when its dataset has ground truth; rows keyed by t_s as frames.csv writes it).

With --angle-deg A each outcome also says how many of its loops are at least A degrees apart, and the
distance range of the others.

Usage: /usr/bin/python3 scripts/loop_edges_truth.py RUN_DIR [--per-loop] [--angle-deg A]
"""
import argparse
import csv
import math
import os
import sys


def read_csv_rows(path, columns):
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        sys.exit(f"{path}: {e.strerror}")
    if rows and not all(c in rows[0] for c in columns):
        sys.exit(f"{path}: expected the columns {', '.join(columns)}")
    return rows


def read_truth(path):
    truth = {}
    try:
        with open(path) as f:
            for line_no, line in enumerate(f, 1):
                line = line.strip()
                if not line or line.startswith("#"):
                    continue
                v = line.split()
                if len(v) != 8:
                    sys.exit(f"{path}:{line_no}: expected 8 values (TUM: t x y z qx qy qz qw), got {len(v)}")
                truth[v[0]] = ([float(x) for x in v[1:4]], [float(x) for x in v[4:8]])
    except OSError as e:
        sys.exit(f"{path}: {e.strerror} (the run writes it only when its dataset has ground truth)")
    return truth


def angle_deg(q1, q2):
    dot = abs(sum(a * b for a, b in zip(q1, q2)))
    norm = math.sqrt(sum(a * a for a in q1) * sum(b * b for b in q2))
    return math.degrees(2.0 * math.acos(min(1.0, dot / norm)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dir")
    ap.add_argument("--per-loop", action="store_true", help="one line per loop before the ranges")
    ap.add_argument("--angle-deg", type=float, help="split each outcome at this angle")
    args = ap.parse_args()
    edges = read_csv_rows(os.path.join(args.run_dir, "loop_edges.csv"), ["i", "j", "verified", "reason"])
    frames = read_csv_rows(os.path.join(args.run_dir, "frames.csv"), ["frame", "t_s"])
    truth = read_truth(os.path.join(args.run_dir, "ground_truth.tum"))
    t_of = {r["frame"]: r["t_s"] for r in frames}
    groups = {}
    for e in edges:
        if e["verified"] == "skipped":
            continue
        poses = []
        for frame in (e["i"], e["j"]):
            t = t_of.get(frame)
            if t is None or t not in truth:
                sys.exit(f"loop ({e['i']}, {e['j']}): frame {frame} has no ground-truth pose")
            poses.append(truth[t])
        (p_i, q_i), (p_j, q_j) = poses
        distance = math.dist(p_i, p_j)
        angle = angle_deg(q_i, q_j)
        if e["verified"] == "y":
            outcome = "verified"
        elif "tracked:" in e["reason"]:
            outcome = "rejected, tracking fallback tried"
        else:
            outcome = "rejected"
        if args.per_loop:
            print(f"{e['i']:>6} {e['j']:>6}  {distance:6.2f} m {angle:6.1f} deg  {outcome}")
        groups.setdefault(outcome, []).append((distance, angle))
    for outcome, values in sorted(groups.items()):
        d = [v[0] for v in values]
        a = [v[1] for v in values]
        line = f"{outcome}: {len(values)} loops, {min(d):.2f}-{max(d):.2f} m and {min(a):.1f}-{max(a):.1f} deg apart"
        if args.angle_deg is not None:
            wide = [v for v in values if v[1] >= args.angle_deg]
            rest = [v[0] for v in values if v[1] < args.angle_deg]
            line += f"; {len(wide)} at least {args.angle_deg:g} deg apart"
            if rest:
                line += f", the other {len(rest)} {min(rest):.2f}-{max(rest):.2f} m apart"
        print(line)


if __name__ == "__main__":
    main()
