#!/usr/bin/python3
"""Pictures of a loopgate run or compare (PNG, matplotlib Agg; python3 + numpy + matplotlib only).

Usage:
  /usr/bin/python3 scripts/plot.py run RUN_DIR [--out DIR]          (default out: RUN_DIR/plots)
  /usr/bin/python3 scripts/plot.py compare COMPARE_DIR [--out DIR]  (default out: COMPARE_DIR/plots)
  /usr/bin/python3 scripts/plot.py aggregate AGG_DIR [--out DIR]    (default out: AGG_DIR)
  /usr/bin/python3 scripts/plot.py scaling BENCH_DIR [--out DIR]    (bench/scaling.sh's folder)
Prints the paths written, one per line, on stdout. Bad input: a message naming the file (and line) on
stderr, exit 2. A missing optional input skips the plot that needs it, with a note on stderr.

Inputs (written by `loopgate run` / `loopgate compare`; every CSV has a header line and is read by column
NAME, cells may be empty; frame indices are dataset frame indices):
  frames.csv           seq,frame,t_ns,t_s,x_m,y_m,z_m,...,status,reason; gated runs add nearest_frame,
                       gate_d_m,gate_threshold_m,gated (y/n),area_id; detection runs add descriptor,...
  loops.csv            i,j,t_i,t_j,score (i query, j earlier reference frame)         (optional)
  ground_truth.tum     "t x y z qx qy qz qw" per frame, matched to frames.csv by nearest t (optional)
  truth_loops.csv      i,j ground-truth loop pairs                                      (optional)
  candidate_areas.csv  id,row_begin,row_end,col_begin,col_end,... (rows = i, cols = j)  (optional)
  timing.csv           seq,frame,<stage>_ms...,latency_ms,total_ms[,decode_cpu_ms,describe_cpu_ms,
                       match_cpu_ms,rest_cpu_ms] (optional; the last four: the time accounting's parts)
  summary.json         "mode", "method", "score_order", "config": {"eval": {...}}, and with ground
                       truth "evaluation": {"truth": {radius_m, gap_frames, plane, accept_radius_m},
                       "precision_recall": {"curve": [{threshold, precision, recall}...],
                       "average_precision", "recall_at_100", ...}} (a top-level "precision_recall"
                       is read too)
  descriptor.csv       "frame,v0,...,v3455" one DIRD descriptor (54 x 64 bytes)       (optional)
  compare.json         {"full": summary, "gated": summary, "seqslam": summary} (any subset), with the
                       run directories COMPARE_DIR/full, COMPARE_DIR/gated, COMPARE_DIR/seqslam.
  aggregate.csv        (`loopgate aggregate`) run,method,...,average_precision,...,wall_s,
                       describe_match_ms,...: one row per run and method, empty cells where a run has no value

Pictures:
  run      trajectory.png  estimated (and ground-truth) trajectory in the two axes of largest extent,
                           true-loop frames marked, detected loops as segments (green true, red false)
           plane.png       (reference j, query i) plane: true loops, odometry-gated pairs, candidate
                           areas (rectangles), detections coloured by correctness (paper Fig. 6)
           timing.png      per-frame time of each stage (stacked) and the total
           pr.png          PR curve (when summary.json has one)
           descriptor.png  the DIRD descriptor as a 54 x 64 grey picture (paper Fig. 3)
           correction.png  with loop correction (trajectory_corrected.tum): ground truth, the odometry and
                           the corrected trajectory, each aligned as its ATE is (summary.json's
                           trajectory_accuracy[_corrected].T_gt_est), ATE RMSE in the legend
  compare  pr.png          PR curves of every method, AP and R@P100 in the legend (paper Fig. 9/12)
           time_per_frame.png  describe+match(+decode) time per frame and cumulative, full vs gated,
                           medians in the legend (paper Fig. 8/11)
           plane.png, trajectory.png  of the gated run
           correction.png  with loop correction (compare.json's "loop_correction"): ground truth, the
                           odometry and every method's corrected trajectory, ATE RMSE in the legend
  aggregate aggregate.png  per run (groups) and method (bars): average precision above; below the
                           describe+match+decode time summed over frames (bars; describe+match without
                           a describe_match_decode_ms column) and the wall time (black ticks), in seconds
  scaling  scaling.png     per-frame describe + match time against the frame index (p50/p99 per bin) and
                           cumulative, of the largest run of each mode (paper Fig. 8 at scale)
A detection is true when the ground-truth positions of i and j are within config.eval.accept_radius_m
(in config.eval.plane when given, else 3-D) and at least min_travel_m of ground-truth path apart, else (or with
eval.truth_pairs_file) when (i, j) is listed in truth_loops.csv. Without truth_loops.csv, true loops are
computed from ground truth: j <= i - gap_frames within radius_m, min_travel_m of path apart.
"""
import argparse
import csv
import json
import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

DPI = 120
DESCRIPTOR_SHAPE = (54, 64)  # DIRD (byte): 3456 values, row-major
DEFAULT_RADIUS_M = 2.0  # evaluation.md defaults when the summary does not say
DEFAULT_GAP_FRAMES = 20
PAIR_BLOCK_CELLS = 1 << 21  # (i, j) cells per block when computing true loops from ground truth
METHOD_LABELS = {"full": "full DIRD", "gated": "gated DIRD", "seqslam": "SeqSLAM",
                 "seqslam-gated": "gated SeqSLAM", "std-full": "full std. DIRD", "std-gated": "gated std. DIRD",
                 "dird-seqslam": "full DIRD-SeqSLAM", "dird-seqslam-gated": "gated DIRD-SeqSLAM"}
AXES = "xyz"


class InputError(Exception):
    """Bad or missing input; the message names the file (and line)."""


def note(message):
    print(f"plot.py: note: {message}", file=sys.stderr)


class Table:
    """A CSV file with a header line, columns accessed by name."""

    def __init__(self, path, required=()):
        self.path = path
        if not path.is_file():
            raise InputError(f"{path}: file not found")
        with open(path, newline="", errors="replace") as f:  # bad bytes then fail as bad cells
            reader = csv.reader(f)
            try:
                self._read(reader, required)
            except csv.Error as e:
                raise InputError(f"{path}:{reader.line_num + 1}: not CSV text: {e}") from None

    def _read(self, reader, required):
        self.header = next(reader, None)
        if not self.header:
            raise InputError(f"{self.path}:1: empty file, expected a header line")
        missing = [c for c in required if c not in self.header]
        if missing:
            raise InputError(f"{self.path}:1: missing column(s) {', '.join(missing)} in the header")
        self.rows, self.lines = [], []
        for row in reader:
            if not row:
                continue
            if len(row) != len(self.header):
                raise InputError(f"{self.path}:{reader.line_num}: expected {len(self.header)} fields "
                                 f"({','.join(self.header)}), got {len(row)}")
            self.rows.append(row)
            self.lines.append(reader.line_num)

    def has(self, column):
        return column in self.header

    def column(self, name):
        if name not in self.header:
            raise InputError(f"{self.path}:1: missing column '{name}' in the header")
        return self.header.index(name)

    def text(self, column):
        k = self.column(column)
        return [row[k] for row in self.rows]

    def indices(self, column):
        """Column of frame indices (non-negative integers) as an int array."""
        values = self.numbers(column, integer=True)
        bad = np.nonzero(values < 0)[0]
        if len(bad):
            raise InputError(f"{self.path}:{self.lines[bad[0]]}: column '{column}': expected a frame index "
                             f">= 0, got {values[bad[0]]:.0f}")
        return values.astype(int)

    def numbers(self, column, integer=False, allow_empty=False):
        """Column as a float array (NaN where empty and allowed)."""
        k = self.column(column)
        out = np.empty(len(self.rows))
        for n, row in enumerate(self.rows):
            cell = row[k].strip()
            try:
                if cell == "" and allow_empty:
                    value = math.nan
                else:
                    value = float(cell)
                    if integer and not value.is_integer():
                        raise ValueError
            except ValueError:
                kind = "an integer" if integer else "a number"
                raise InputError(f"{self.path}:{self.lines[n]}: column '{column}': expected {kind}, "
                                 f"got '{cell}'") from None
            out[n] = value
        return out


def read_json(path):
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    try:
        with open(path) as f:
            value = json.load(f)
    except json.JSONDecodeError as e:
        raise InputError(f"{path}:{e.lineno}: invalid JSON: {e.msg}") from None
    except UnicodeDecodeError as e:
        raise InputError(f"{path}: not JSON text: {e}") from None
    if not isinstance(value, dict):
        raise InputError(f"{path}:1: expected a JSON object")
    return value


def precision_recall(summary):
    """The PR block of a summary: "evaluation.precision_recall" (loopgate run), else a top-level one."""
    return section(summary, "evaluation", "precision_recall") or section(summary, "precision_recall")


def section(mapping, *keys):
    """Nested JSON object at keys, or {} when absent or not an object."""
    for key in keys:
        mapping = mapping.get(key) if isinstance(mapping, dict) else None
    return mapping if isinstance(mapping, dict) else {}


def read_tum(path):
    """Returns (t_s, xyz) of a TUM trajectory file."""
    times, xyz = [], []
    with open(path, errors="replace") as f:
        for line_no, line in enumerate(f, 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            try:
                values = [float(v) for v in line.split()]
            except ValueError:
                values = []
            if len(values) != 8:
                raise InputError(f"{path}:{line_no}: expected 8 numbers 't x y z qx qy qz qw'")
            times.append(values[0])
            xyz.append(values[1:4])
    if not times:
        raise InputError(f"{path}: no poses")
    return np.array(times), np.array(xyz)


def frame_array(frames, values, size):
    """Scatters per-row values (n x d) into an array indexed by frame (NaN where absent)."""
    out = np.full((size,) + values.shape[1:], np.nan)
    out[frames.astype(int)] = values
    return out


def distances(a, b, plane):
    keep = [AXES.index(c) for c in plane]
    return np.linalg.norm(a[..., keep] - b[..., keep], axis=-1)


class Run:
    """Everything plot-worthy of one run directory."""

    def __init__(self, run_dir):
        self.dir = run_dir
        self.summary = read_json(run_dir / "summary.json")
        # The ground-truth parameters the run used (summary "evaluation.truth"), else its config echo.
        ev = section(self.summary, "evaluation", "truth") or section(self.summary, "config", "eval")
        try:
            radius_m = float(ev.get("radius_m", 0))
            accept_m = float(ev.get("accept_radius_m", 0))
            self.gap = int(ev.get("gap_frames", DEFAULT_GAP_FRAMES))
        except (TypeError, ValueError):
            raise InputError(f"{run_dir / 'summary.json'}: config.eval: radius_m, accept_radius_m and "
                             "gap_frames must be numbers") from None
        self.radius_m = radius_m if radius_m > 0 else DEFAULT_RADIUS_M  # <= 0: the default
        self.accept_m = accept_m if accept_m > 0 else self.radius_m  # <= 0: r_accept = r_true
        self.plane = ev.get("plane") if ev.get("plane") in ("xy", "xz", "yz", "xyz") else "xyz"
        try:  # eval.min_travel_m: a revisit needs this much ground-truth path in between (absent: none)
            self.min_travel_m = float(ev.get("min_travel_m", 0) or 0)
        except (TypeError, ValueError):
            raise InputError(f"{run_dir / 'summary.json'}: min_travel_m must be a number") from None
        # eval.truth_pairs_file: the listed pairs are the truth, even when the dataset has poses.
        self.pairs_truth = "pairs_file" in (section(self.summary, "evaluation", "truth") or {})

        f = Table(run_dir / "frames.csv", ["frame", "x_m", "y_m", "z_m"])
        self.frames_table = f
        frame = f.indices("frame")
        loops_path = run_dir / "loops.csv"
        self.loops = Table(loops_path, ["i", "j", "score"]) if loops_path.is_file() else None
        self.i = self.loops.indices("i") if self.loops else np.zeros(0, int)
        self.j = self.loops.indices("j") if self.loops else np.zeros(0, int)
        truth_path = run_dir / "truth_loops.csv"
        self.truth = None
        if truth_path.is_file():
            t = Table(truth_path, ["i", "j"])
            self.truth = np.stack([t.indices("i"), t.indices("j")], 1).reshape(-1, 2)
        sizes = [frame.max(initial=-1), self.i.max(initial=-1), self.j.max(initial=-1)]
        if self.truth is not None:
            sizes.append(self.truth.max(initial=-1))
        self.size = int(max(sizes)) + 1
        xyz = np.stack([f.numbers(c, allow_empty=True) for c in ("x_m", "y_m", "z_m")], 1)
        self.est = frame_array(frame, xyz, self.size)

        self.gt = None
        gt_path = run_dir / "ground_truth.tum"
        if gt_path.is_file():
            t_gt, xyz_gt = read_tum(gt_path)
            if f.has("t_s"):
                t = f.numbers("t_s", allow_empty=True)
            else:
                t = f.numbers("t_ns", allow_empty=True) * 1e-9
            order = np.argsort(t_gt)
            t_gt, xyz_gt = t_gt[order], xyz_gt[order]
            k = np.clip(np.searchsorted(t_gt, t), 1, len(t_gt) - 1)
            k = np.where(np.abs(t_gt[k - 1] - t) <= np.abs(t_gt[k] - t), k - 1, k)
            matched = np.where(np.isfinite(t)[:, None], xyz_gt[k], np.nan)
            self.gt = frame_array(frame, matched, self.size)
            # Ground-truth path length from the first frame (3-D; straight across frames without ground truth).
            finite = np.isfinite(self.gt).all(axis=1)
            steps = np.zeros(self.size)
            idx = np.flatnonzero(finite)
            if len(idx) > 1:
                steps[idx[1:]] = np.linalg.norm(np.diff(self.gt[idx], axis=0), axis=1)
            self.travel = np.cumsum(steps)

        areas_path = run_dir / "candidate_areas.csv"
        self.areas = None
        if areas_path.is_file():
            a = Table(areas_path, ["id", "row_begin", "row_end", "col_begin", "col_end"])
            self.areas = np.stack([a.numbers(c, integer=True) for c in
                                   ("row_begin", "row_end", "col_begin", "col_end")], 1)
        timing_path = run_dir / "timing.csv"
        self.timing = Table(timing_path, ["frame"]) if timing_path.is_file() else None
        if self.gt is None and self.truth is None:
            note(f"{run_dir}: no ground_truth.tum or truth_loops.csv: loops are drawn unchecked")
        if self.loops is None:
            note(f"{loops_path}: absent, no detections drawn")

    def loop_correct(self, i, j):
        """Boolean array (is each (i, j) a true loop), or None without any ground truth."""
        if self.gt is not None and not (self.pairs_truth and self.truth is not None):
            travelled = np.abs(self.travel[i] - self.travel[j]) >= self.min_travel_m
            return (distances(self.gt[i], self.gt[j], self.plane) <= self.accept_m) & travelled
        if self.truth is not None:
            listed = set(map(tuple, self.truth.tolist()))
            return np.array([(a, b) in listed for a, b in zip(i.tolist(), j.tolist())], bool)
        return None

    def true_pairs(self):
        """(n x 2) ground-truth loop pairs (i, j), or None; computed once."""
        if not hasattr(self, "_true_pairs"):
            self._true_pairs = self.truth if self.truth is not None else self._pairs_from_ground_truth()
        return self._true_pairs

    def _pairs_from_ground_truth(self):
        if self.gt is None:
            return None
        pairs = [np.zeros((0, 2), int)]
        chunk = max(1, PAIR_BLOCK_CELLS // max(1, self.size))  # bounded memory on long sequences
        for start in range(0, self.size, chunk):
            rows = np.arange(start, min(start + chunk, self.size))
            d = distances(self.gt[rows][:, None, :], self.gt[None, :, :], self.plane)
            ok = (d <= self.radius_m) & (np.arange(self.size)[None, :] <= rows[:, None] - self.gap)
            ok &= self.travel[rows][:, None] - self.travel[None, :] >= self.min_travel_m
            r, c = np.nonzero(ok)
            pairs.append(np.stack([rows[r], c], 1))
        return np.concatenate(pairs)


def save(fig, path, written, dpi=DPI):
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    written.append(path)


def detection_groups(run, true_colour):
    """(mask, colour, label) of the detections to draw: true/false when there is ground truth."""
    correct = run.loop_correct(run.i, run.j)
    if correct is None:
        return [(np.ones(len(run.i), bool), "tab:purple", "detections (unchecked)")]
    return [(correct, true_colour, "detections, true"), (~correct, "tab:red", "detections, false")]


def finish_plane_axes(fig, ax, axes, title, path, written):
    """Labels, equal aspect, legend and grid of a top view in world axes `axes`, then saves it."""
    ax.set_xlabel(f"{AXES[axes[0]]} [m]")
    ax.set_ylabel(f"{AXES[axes[1]]} [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(title)
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    save(fig, path, written)


def plot_trajectory(run, path, written, title):
    clouds = [p for p in (run.est, run.gt) if p is not None and np.isfinite(p).any()]
    if not clouds:
        note(f"{run.dir / 'frames.csv'}: no finite positions, trajectory.png skipped")
        return
    extent = np.nanmax(np.concatenate(clouds), 0) - np.nanmin(np.concatenate(clouds), 0)
    a, b = sorted(np.argsort(-extent)[:2])
    fig, ax = plt.subplots(figsize=(8, 7))
    if run.gt is not None:
        ax.plot(run.gt[:, a], run.gt[:, b], color="0.55", lw=1.2, label="ground truth")
    ax.plot(run.est[:, a], run.est[:, b], color="tab:blue", lw=0.9, label="estimated (frames.csv)")
    base = run.gt if run.gt is not None else run.est
    truth = run.true_pairs()
    if truth is not None and len(truth):
        q = np.unique(truth[:, 0])
        ax.scatter(base[q, a], base[q, b], s=14, color="gold", edgecolor="none", zorder=3,
                   label=f"true-loop frames ({len(q)})")
    if len(run.i):
        seg = np.stack([base[run.i][:, [a, b]], base[run.j][:, [a, b]]], 1)
        for mask, colour, label in detection_groups(run, "tab:green"):  # segment, and a dot at query i
            ax.add_collection(LineCollection(seg[mask], colors=colour, lw=1.0, zorder=4))
            ax.plot(seg[mask, 0, 0], seg[mask, 0, 1], "o", ms=3.5, color=colour, zorder=5,
                    label=f"{label} ({int(mask.sum())})")
    finish_plane_axes(fig, ax, (a, b), title, path, written)


def aligned_xyz(path, accuracy):
    """Positions of a TUM file under the ATE's alignment T_gt_est (3 x 4 rows), or None without one."""
    if not accuracy or not accuracy.get("available") or "T_gt_est" not in accuracy or not path.is_file():
        return None
    T = np.array(accuracy["T_gt_est"], dtype=float)
    if T.shape != (3, 4):
        raise InputError(f"{path}: T_gt_est is not 3 x 4")
    _, xyz = read_tum(path)
    return xyz @ T[:, :3].T + T[:, 3]


def plot_correction(gt_path, odometry, corrected, path, written, title):
    """odometry: (label, xyz, ate_m); corrected: list of (label, xyz, ate_m). Drawn in the two axes of
    largest extent of the ground truth."""
    if not corrected or not gt_path.is_file():
        return
    _, gt = read_tum(gt_path)
    extent = np.ptp(gt, 0)
    a, b = sorted(np.argsort(-extent)[:2])
    fig, ax = plt.subplots(figsize=(8, 7))
    ax.plot(gt[:, a], gt[:, b], color="0.55", lw=2.0, label="ground truth")
    if odometry is not None:
        label, xyz, ate = odometry
        ax.plot(xyz[:, a], xyz[:, b], color="tab:red", lw=0.9, label=f"{label}: ATE {ate:.3f} m")
    colours = ["tab:blue", "tab:green", "tab:purple", "tab:orange", "tab:cyan", "tab:olive", "tab:brown",
               "tab:pink"]
    for k, (label, xyz, ate) in enumerate(corrected):
        ax.plot(xyz[:, a], xyz[:, b], color=colours[k % len(colours)], lw=0.9,
                label=f"{label}: ATE {ate:.3f} m")
    finish_plane_axes(fig, ax, (a, b), title, path, written)


def correction_lines(run_dir, summary, corrected_fields, label):
    """(odometry line, corrected line) of a run with loop correction, or (None, None)."""
    before = summary.get("trajectory_accuracy")
    after = corrected_fields.get("trajectory_accuracy_corrected")
    odo = aligned_xyz(run_dir / "trajectory.tum", before)
    cor = aligned_xyz(run_dir / "trajectory_corrected.tum", after)
    if odo is None or cor is None:
        return None, None
    return ("odometry", odo, before["rmse_m"]), (label, cor, after["rmse_m"])


def plot_plane(run, path, written, title):
    truth = run.true_pairs()
    f = run.frames_table
    gated = None
    if f.has("gated") and f.has("nearest_frame"):
        mask = np.array([g.strip() == "y" for g in f.text("gated")])
        near = f.numbers("nearest_frame", integer=True, allow_empty=True)
        mask &= np.isfinite(near)
        gated = (f.numbers("frame", integer=True)[mask], near[mask])
    if truth is None and run.areas is None and not len(run.i) and (gated is None or not len(gated[0])):
        note(f"{run.dir}: no ground truth, candidate areas, gated frames or loops: plane.png skipped")
        return
    fig, ax = plt.subplots(figsize=(8, 7))
    if truth is not None and len(truth):
        ax.scatter(truth[:, 1], truth[:, 0], s=8, color="tab:green", alpha=0.3, edgecolor="none",
                   label=f"true loops ({len(truth)} pairs)")
    if gated is not None and len(gated[0]):
        ax.scatter(gated[1], gated[0], s=6, marker="x", color="0.5", lw=0.6,
                   label=f"odometry-gated nearest ({len(gated[0])})")
    if run.areas is not None:
        for n, (r0, r1, c0, c1) in enumerate(run.areas):
            ax.add_patch(Rectangle((c0 - 0.5, r0 - 0.5), c1 - c0 + 1, r1 - r0 + 1, fill=False,
                                   edgecolor="red", lw=1.2, label="candidate areas" if n == 0 else None))
    if len(run.i):
        for mask, colour, label in detection_groups(run, "tab:blue"):
            ax.scatter(run.j[mask], run.i[mask], s=10, color=colour, zorder=4,
                       label=f"{label} ({int(mask.sum())})")
    ax.plot([0, run.size], [0, run.size], ls=":", color="0.6", lw=0.8)
    ax.set_xlim(0, run.size)
    ax.set_ylim(0, run.size)
    ax.set_xlabel("reference frame j")
    ax.set_ylabel("query frame i")
    ax.set_title(title)
    ax.legend(loc="lower right", fontsize=8, markerscale=2)  # j > i is empty: references are earlier
    ax.grid(alpha=0.3)
    save(fig, path, written)


NOT_STAGES = ("latency_ms", "total_ms", "decode_cpu_ms", "describe_cpu_ms", "match_cpu_ms", "rest_cpu_ms")


def stage_columns(table):
    return [c for c in table.header if c.endswith("_ms") and c not in NOT_STAGES]


def plot_timing(run, path, written):
    t = run.timing
    if t is None:
        note(f"{run.dir / 'timing.csv'}: absent, timing.png skipped")
        return
    frame = t.numbers("frame", integer=True)
    stages = stage_columns(t)
    fig, ax = plt.subplots(figsize=(10, 5))
    if stages:
        values = [np.nan_to_num(t.numbers(c, allow_empty=True)) for c in stages]
        ax.stackplot(frame, values, labels=[f"{c[:-3]} (median {np.median(v):.3g} ms)"
                                            for c, v in zip(stages, values)], alpha=0.8)
    if t.has("total_ms"):
        total = t.numbers("total_ms", allow_empty=True)
        ax.plot(frame, total, color="black", lw=0.6, label=f"total (median {np.nanmedian(total):.3g} ms)")
    ax.set_xlabel("frame")
    ax.set_ylabel("time per frame [ms]")
    ax.set_title(f"{run.dir.name}: per-frame time by stage")
    ax.legend(loc="upper left", fontsize=8)
    ax.grid(alpha=0.3)
    save(fig, path, written)


def plot_descriptor(run_dir, path, written):
    src = run_dir / "descriptor.csv"
    if not src.is_file():
        note(f"{src}: absent, descriptor.png skipped")
        return
    size = DESCRIPTOR_SHAPE[0] * DESCRIPTOR_SHAPE[1]
    row, line_no = None, 0
    with open(src, newline="", errors="replace") as f:
        for line_no, cells in enumerate(csv.reader(f), 1):
            if not cells or (line_no == 1 and not cells[0].strip().lstrip("-").isdigit()):
                continue  # blank line or header
            row = cells
            break
    if row is None:
        raise InputError(f"{src}: no descriptor line")
    if len(row) != size + 1:
        raise InputError(f"{src}:{line_no}: expected {size + 1} fields (frame, v0..v{size - 1}), "
                         f"got {len(row)}")
    try:
        values = np.array([float(v) for v in row[1:]])
    except ValueError:
        raise InputError(f"{src}:{line_no}: expected numbers") from None
    fig, ax = plt.subplots(figsize=(6, 5.4))
    ax.imshow(values.reshape(DESCRIPTOR_SHAPE), cmap="gray", vmin=0, vmax=255, interpolation="nearest")
    ax.set_title(f"DIRD descriptor of frame {row[0]} (54 x 64 bytes)")
    ax.set_xticks([])
    ax.set_yticks([])
    save(fig, path, written)


def plot_pr(summaries, path, written, source):
    fig, ax = plt.subplots(figsize=(7, 6))
    drawn = 0
    for name, summary in summaries.items():
        pr = precision_recall(summary)
        if not pr.get("curve"):
            note(f"{source}: '{name}' has no precision-recall curve (no detection): left out of pr.png")
            continue
        try:
            recall = [float(p["recall"]) for p in pr["curve"]]
            precision = [float(p["precision"]) for p in pr["curve"]]
            ap, r100 = float(pr.get("average_precision", 0)), float(pr.get("recall_at_100", 0))
        except (KeyError, TypeError, ValueError):
            raise InputError(f"{source}: '{name}'.precision_recall: expected numeric curve points "
                             "(precision, recall), average_precision and recall_at_100") from None
        label = f"{METHOD_LABELS.get(name, name)} (AP {ap:.3f}, R@P100 {r100:.3f})"
        ax.plot([0.0] + recall, precision[:1] + precision, drawstyle="steps-pre", lw=1.5, label=label)
        drawn += 1
    if not drawn:
        plt.close(fig)
        note(f"{source}: no ground truth (no precision_recall), pr.png skipped")
        return
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_title("precision-recall")
    if drawn > 4:  # many methods: the legend below the axes, where it covers no curve
        fig.set_size_inches(7, 6 + 0.25 * ((drawn + 1) // 2))
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=8)
    else:
        ax.legend(loc="lower left", fontsize=9)
    ax.grid(alpha=0.3)
    save(fig, path, written)


def plot_time_per_frame(runs, path, written):
    """runs: {name: Run} with timing; describe + match (+ decode when present) per frame, plus the time other
    threads spent in those stages' parallel loops: the time accounting's thread CPU time (decode_cpu_ms,
    describe_cpu_ms, match_cpu_ms) as in compare's table, else the stages' service time."""
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 8), sharex=True)
    for name, run in runs.items():
        parts = [c for c in ("decode_cpu_ms", "describe_cpu_ms", "match_cpu_ms") if run.timing.has(c)]
        parts = parts or [c for c in ("decode_ms", "describe_ms", "match_ms") if run.timing.has(c)]
        if not parts:
            raise InputError(f"{run.dir / 'timing.csv'}:1: no describe_ms/match_ms/decode_ms column")
        frame = run.timing.numbers("frame", integer=True)
        total = sum(np.nan_to_num(run.timing.numbers(c, allow_empty=True)) for c in parts)
        label = f"{METHOD_LABELS.get(name, name)}: {'+'.join(c[:-3].replace('_cpu', '') for c in parts)}"
        top.plot(frame, total, lw=0.7, label=f"{label} (median {np.median(total):.3g} ms)")
        bottom.plot(frame, np.cumsum(total), lw=1.2, label=f"{label} (total {total.sum():.1f} ms)")
    top.set_ylabel("time per frame [ms]")
    top.set_title("loop-closure time per frame: full vs gated")
    bottom.set_ylabel("cumulative time [ms]")
    bottom.set_xlabel("frame")
    for ax in (top, bottom):
        ax.legend(loc="upper left", fontsize=8)
        ax.grid(alpha=0.3)
    save(fig, path, written)


def title_of(run):
    s = run.summary
    mode = s.get("mode") or section(s, "config", "run").get("mode", "?")
    return f"{run.dir.name}: mode {mode}, method {s.get('method', 'dird')}"


def cmd_run(run_dir, out):
    written = []
    run = Run(run_dir)
    plot_trajectory(run, out / "trajectory.png", written, title_of(run))
    plot_plane(run, out / "plane.png", written, title_of(run))
    plot_timing(run, out / "timing.png", written)
    if precision_recall(run.summary):
        method = run.summary.get("method", "dird")
        mode = run.summary.get("mode", "full")
        if method == "dird":
            name = mode  # "full" / "gated" DIRD
        else:  # "seqslam" / "seqslam-gated", "dird-seqslam" / "dird-seqslam-gated"
            name = method if mode != "gated" else f"{method}-gated"
        plot_pr({name: run.summary}, out / "pr.png", written, run_dir / "summary.json")
    plot_descriptor(run_dir, out / "descriptor.png", written)
    odo, cor = correction_lines(run_dir, run.summary, run.summary, "corrected (pose graph)")
    if cor is not None:
        plot_correction(run_dir / "ground_truth.tum", odo, [cor], out / "correction.png", written,
                        f"{run_dir.name}: loop correction")
    return written


def cmd_compare(compare_dir, out):
    written = []
    source = compare_dir / "compare.json"
    summaries = {name: value for name, value in read_json(source).items()  # other keys: not methods
                 if isinstance(value, dict) and (name in METHOD_LABELS or "precision_recall" in value)}
    if not summaries:
        raise InputError(f"{source}:1: expected method summaries (full, gated, seqslam)")
    plot_pr(summaries, out / "pr.png", written, source)
    if any(s.get("mode") == "two-sequence" for s in summaries.values()):
        note(f"{source}: two-sequence runs (no poses): only pr.png")
        return written
    runs = {}
    for name in ("full", "gated"):  # the run directories whose files are plotted
        if name in summaries:
            if not (compare_dir / name).is_dir():
                raise InputError(f"{source}: lists '{name}' but {compare_dir / name} is not a directory")
            runs[name] = Run(compare_dir / name)
    timed = {name: run for name, run in runs.items() if run.timing is not None}
    for name in set(runs) - set(timed):
        note(f"{compare_dir / name / 'timing.csv'}: absent")
    if timed:
        plot_time_per_frame(timed, out / "time_per_frame.png", written)
    else:
        note(f"{compare_dir}: no timing of full or gated, time_per_frame.png skipped")
    if "gated" in runs:
        title = f"{compare_dir.resolve().name}: gated DIRD"
        plot_plane(runs["gated"], out / "plane.png", written, title)
        plot_trajectory(runs["gated"], out / "trajectory.png", written, title)
    else:
        note(f"{source}: no gated run, plane.png and trajectory.png skipped")
    odometry, corrected, gt_path = None, [], None
    for name, summary in summaries.items():
        if "loop_correction" not in summary:
            continue
        odo, cor = correction_lines(compare_dir / name, summary, summary["loop_correction"],
                                    f"corrected, {METHOD_LABELS.get(name, name)}")
        if cor is None:
            continue
        odometry = odometry or odo  # the same odometry in every method's run
        corrected.append(cor)
        gt_path = gt_path or compare_dir / name / "ground_truth.tum"
    if corrected:
        plot_correction(gt_path, odometry, corrected, out / "correction.png", written,
                        f"{compare_dir.resolve().name}: loop correction")
    return written


def cmd_aggregate(agg_dir, out):
    """aggregate.png of `loopgate aggregate`'s table: AP and time per run and method."""
    written = []
    table = Table(agg_dir / "aggregate.csv",
                  required=("run", "method", "average_precision", "wall_s", "describe_match_ms"))
    if not table.rows:
        raise InputError(f"{table.path}:2: no rows (expected one per run and method)")
    runs_col, methods_col = table.text("run"), table.text("method")
    ap = table.numbers("average_precision", allow_empty=True)
    wall_s = table.numbers("wall_s", allow_empty=True)
    # Full runs decode every frame in the decode stage, gated ones inside describe: with decode is the fair sum.
    detect_column = "describe_match_ms"
    if table.has("describe_match_decode_ms"):
        detect_column = "describe_match_decode_ms"
    detect_s = table.numbers(detect_column, allow_empty=True) / 1000.0
    runs = list(dict.fromkeys(runs_col))
    methods = list(dict.fromkeys(methods_col))
    width = 0.8 / len(methods)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(max(8.0, 1.2 + 0.35 * len(runs) * len(methods)), 8),
                                      sharex=True)
    colours = plt.get_cmap("tab10")
    for m, method in enumerate(methods):
        rows = [k for k, name in enumerate(methods_col) if name == method]
        x = np.array([runs.index(runs_col[k]) for k in rows]) + (m - (len(methods) - 1) / 2) * width
        colour = colours(m % 10)
        top.bar(x, np.nan_to_num(ap[rows]), width, color=colour, label=METHOD_LABELS.get(method, method))
        for xk, value in zip(x, ap[rows]):
            if np.isnan(value):  # no ground truth: no AP, said rather than drawn as 0
                top.text(xk, 0.01, "n/a", ha="center", va="bottom", fontsize=7, rotation=90)
        bottom.bar(x, np.nan_to_num(detect_s[rows]), width, color=colour)
        bottom.plot(x, wall_s[rows], linestyle="none", marker="_", markersize=10, color="black")
    top.set_ylim(0, 1.05)
    top.set_ylabel("average precision")
    name = agg_dir.resolve().name
    if name == "aggregate":  # loopgate aggregate's default folder: the batch ROOT's name says more
        name = agg_dir.resolve().parent.name
    legend_rows = (len(methods) + 3) // 4
    top.set_title(f"{name}: average precision and time per run and method", pad=12 + 14 * legend_rows)
    top.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=min(4, len(methods)), fontsize=8,
               frameon=False)
    what = "describe+match+decode" if detect_column == "describe_match_decode_ms" else "describe+match"
    bottom.set_ylabel(f"time [s]: {what} summed\nover frames (bars), wall (ticks)")
    positive = np.concatenate([detect_s[detect_s > 0], wall_s[wall_s > 0]])
    if len(positive) and positive.max() / positive.min() > 100:
        bottom.set_yscale("log")
    bottom.set_xticks(range(len(runs)))
    bottom.set_xticklabels(runs, rotation=30, ha="right", fontsize=8)
    for ax in (top, bottom):
        ax.grid(alpha=0.3, axis="y")
    save(fig, out / "aggregate.png", written)
    return written


def frame_detection_ms(timing):
    """Per-frame loop-detection time of a timing.csv, thread CPU time: describe (without the images decoded
    inside it) + match, both with other threads' time in their parallel loops; and the per-frame decode time
    (the decode stage + the images decoded inside describe)."""
    def col(name):
        return np.nan_to_num(timing.numbers(name, allow_empty=False))
    return col("describe_cpu_ms") + col("match_cpu_ms"), col("decode_cpu_ms")


def cmd_scaling(bench_dir, out):
    """bench/scaling.sh's folder: MODE-FRAMES/run/timing.csv per run; the largest run of each mode is drawn
    (paper Fig. 8): per-frame loop-detection time against the frame index (p50 and p99 per bin of frames) and
    the cumulative time."""
    written = []
    runs = {}
    for d in sorted(bench_dir.iterdir()):
        name, _, frames = d.name.rpartition("-")
        if d.is_dir() and name and frames.isdigit() and (d / "run" / "timing.csv").is_file():
            if int(frames) > runs.get(name, (0, None))[0]:
                runs[name] = (int(frames), d / "run")
    if not runs:
        raise InputError(f"{bench_dir}: no MODE-FRAMES/run/timing.csv (run bench/scaling.sh first)")
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for name in sorted(runs):
        frames, run_dir = runs[name]
        timing = Table(run_dir / "timing.csv", ["frame"])
        frame = timing.numbers("frame", integer=True)
        detection, _ = frame_detection_ms(timing)
        bins = 200
        edges = np.linspace(0, len(frame), bins + 1).astype(int)
        centre = [frame[(a + b) // 2] for a, b in zip(edges[:-1], edges[1:]) if b > a]
        p50 = [np.percentile(detection[a:b], 50) for a, b in zip(edges[:-1], edges[1:]) if b > a]
        p99 = [np.percentile(detection[a:b], 99) for a, b in zip(edges[:-1], edges[1:]) if b > a]
        label = METHOD_LABELS.get(name, name)
        line, = top.plot(centre, p99, lw=1.2, label=f"{label}: p99 per {len(frame) // bins} frames")
        top.plot(centre, p50, lw=1.0, ls="--", color=line.get_color(), label=f"{label}: p50")
        every = max(1, len(frame) // 2000)  # the cumulative curve is smooth: 2000 points are enough
        bottom.plot(frame[::every], (np.cumsum(detection) / 1000.0)[::every], lw=1.2, color=line.get_color(),
                    label=f"{label} (total {detection.sum() / 1000.0:.1f} s)")
    top.set_yscale("log")
    top.set_ylabel("loop detection per frame [ms]")
    top.set_title("describe + match per frame as the map grows (thread CPU time; synthetic drive)")
    bottom.set_ylabel("cumulative [s]")
    bottom.set_xlabel("frame")
    top.legend(loc="upper right", fontsize=8)  # full's curve rises on the left
    bottom.legend(loc="upper left", fontsize=8)
    for ax in (top, bottom):
        ax.grid(alpha=0.3, which="both")
    save(fig, out / "scaling.png", written, dpi=90)  # small enough for the docs (docs/img)
    return written


def main():
    parser = argparse.ArgumentParser(description="Pictures of a loopgate run or compare (PNG).")
    parser.add_argument("what", choices=["run", "compare", "aggregate", "scaling"])
    parser.add_argument("dir", type=Path, help="RUN_DIR, COMPARE_DIR, AGG_DIR (loopgate aggregate's --out) or "
                        "the folder of bench/scaling.sh")
    parser.add_argument("--out", type=Path, help="output directory (default: DIR/plots; aggregate: DIR)")
    args = parser.parse_args()
    try:
        if not args.dir.is_dir():
            raise InputError(f"{args.dir}: not a directory")
        out = args.out or (args.dir if args.what == "aggregate" else args.dir / "plots")
        out.mkdir(parents=True, exist_ok=True)
        command = {"run": cmd_run, "compare": cmd_compare, "aggregate": cmd_aggregate,
                   "scaling": cmd_scaling}[args.what]
        written = command(args.dir, out)
    except (InputError, OSError) as e:
        print(f"plot.py: error: {e}", file=sys.stderr)
        return 2
    for path in written:
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
