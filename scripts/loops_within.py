#!/usr/bin/python3
"""Count the loop closures of a run (loops.csv: i,j,t_i,t_j,score) that fall within a radius of ground
truth, per detection and per query frame (its best-scoring detection), at a few score thresholds.

Ground truth: a KITTI poses.txt (3x4 row-major per frame; the position is the last column), or a TUM file
(t x y z qx qy qz qw, one row per frame in frame order). Distance: 3-D Euclidean between the positions of
frames i and j (KITTI camera frame: the ground plane is x-z, y is height and nearly constant).

Usage: /usr/bin/python3 scripts/loops_within.py RUN_DIR/loops.csv POSES [--radius 10] [--tum]
                                                 [--thresholds 1,2,5,10]
The run's summary.json holds the same counts at the configured score threshold (eval.accept_radius_m).
"""
import argparse
import csv
import math
import sys


def read_positions(path, tum):
    positions = []
    with open(path) as f:
        for line_no, line in enumerate(f, 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            v = [float(x) for x in line.replace(",", " ").split()]
            if tum:
                if len(v) != 8:
                    sys.exit(f"{path}:{line_no}: expected 8 values (TUM), got {len(v)}")
                positions.append((v[1], v[2], v[3]))
            else:
                if len(v) != 12:
                    sys.exit(f"{path}:{line_no}: expected 12 values (KITTI 3x4 pose), got {len(v)}")
                positions.append((v[3], v[7], v[11]))
    return positions


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("loops")
    ap.add_argument("poses")
    ap.add_argument("--radius", type=float, default=10.0)
    ap.add_argument("--tum", action="store_true")
    ap.add_argument("--thresholds", default="")
    a = ap.parse_args()
    pos = read_positions(a.poses, a.tum)
    loops = []
    with open(a.loops) as f:
        for row in csv.DictReader(f):
            i, j, score = int(row["i"]), int(row["j"]), float(row["score"])
            if i >= len(pos) or j >= len(pos):
                sys.exit(f"{a.loops}: frame {max(i, j)} beyond the {len(pos)} poses of {a.poses}")
            loops.append((i, j, score, math.dist(pos[i], pos[j])))
    thresholds = [float("-inf")] + [float(t) for t in a.thresholds.split(",") if t]
    print(f"radius {a.radius} m; {len(loops)} detections in {a.loops}")
    print(f"{'score >':>10} {'detections':>10} {'within':>8} {'beyond':>8} {'queries':>8} "
          f"{'best within':>11} {'best beyond':>11}")
    for t in thresholds:
        kept = [l for l in loops if l[2] > t]
        within = sum(1 for l in kept if l[3] <= a.radius)
        best = {}
        for l in kept:  # best-scoring detection per query frame (first on ties)
            if l[0] not in best or l[2] > best[l[0]][2]:
                best[l[0]] = l
        best_within = sum(1 for l in best.values() if l[3] <= a.radius)
        label = "all" if t == float("-inf") else f"{t:g}"
        print(f"{label:>10} {len(kept):>10} {within:>8} {len(kept) - within:>8} {len(best):>8} "
              f"{best_within:>11} {len(best) - best_within:>11}")


if __name__ == "__main__":
    main()
