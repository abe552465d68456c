#!/usr/bin/env python3
"""Digest of a run's deterministic outputs, one line per item: the files that must not change when the code
is only reorganised (loops.csv, frames.csv, trajectory.tum, candidate_cells.csv) and the evaluation block of
summary.json. Used by tests/e2e_golden_test.cpp and by hand to compare two builds:

    /usr/bin/python3 scripts/run_digest.py RUN_DIR [RUN_DIR ...]

A compare folder (with compare.json) is expanded into its method folders. Timing columns are not part of
any of these files; frames.csv is taken whole."""
import hashlib
import json
import os
import sys

FILES = ["loops.csv", "frames.csv", "trajectory.tum", "candidate_cells.csv"]


def digest_run(path, label):
    lines = []
    for name in FILES:
        file = os.path.join(path, name)
        if os.path.exists(file):
            with open(file, "rb") as f:
                lines.append(f"{label}/{name} {hashlib.sha256(f.read()).hexdigest()[:16]}")
    summary = os.path.join(path, "summary.json")
    if os.path.exists(summary):
        with open(summary) as f:
            evaluation = json.load(f).get("evaluation", {})
        text = json.dumps(evaluation, sort_keys=True, separators=(",", ":"))
        lines.append(f"{label}/summary.json:evaluation {hashlib.sha256(text.encode()).hexdigest()[:16]}")
    return lines


def main(argv):
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    out = []
    for path in argv[1:]:
        if not os.path.isdir(path):
            print(f"run_digest: {path}: not a folder", file=sys.stderr)
            return 2
        label = os.path.basename(os.path.normpath(path))
        compare = os.path.join(path, "compare.json")
        if os.path.exists(compare):
            with open(compare) as f:
                methods = json.load(f).get("methods", [])
            for m in methods:
                out += digest_run(os.path.join(path, m), f"{label}/{m}")
        else:
            out += digest_run(path, label)
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
