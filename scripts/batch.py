#!/usr/bin/python3
"""The batch manifest of loopgate (docs/batch.md): parsing, checking, and one job at a time.

scripts/batch.sh (GNU parallel) and scripts/slurm/loopgate-array.sbatch (Slurm job arrays) schedule the jobs;
this file only knows what a job is. Python 3 standard library only.

Usage:
  batch.py check MANIFEST                         every line checked, errors as MANIFEST:LINE: ...
  batch.py indices MANIFEST simulate|runs [--ranges]
                                                  the job numbers of a phase, one per line, or as Slurm
                                                  --array ranges ("1-2,5")
  batch.py prepare MANIFEST [--out ROOT]          before a batch.sh: state folder, manifest copy, the job
                                                  logs kept only while they agree with the outputs
  batch.py job [--out ROOT] [--loopgate BIN] MANIFEST N
                                                  runs job N (1 = the first job line): skipped when done
  batch.py report MANIFEST PHASE [--out ROOT]     after a phase: names the failed jobs (exit 1), or exit 0

A job number counts job lines only (not the header, comments or blank lines), in manifest order: the Slurm
array index. Exit status: 0 ok, 1 a job failed, 2 a bad manifest or usage.
"""
import argparse
import csv
import datetime
import json
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

COLUMNS = ["name", "command", "dataset", "config", "set", "options"]
COMMANDS = ("simulate", "run", "compare")
PHASES = {"simulate": ("simulate",), "runs": ("run", "compare")}
# What says a job's outputs are complete (written last by the command, when it succeeds or stops cleanly).
COMPLETION_FILE = {"simulate": "simulation.json", "run": "summary.json", "compare": "compare.json"}
# Options the columns or batch.sh itself set: not allowed in the options column.
RESERVED_OPTIONS = {"--out": "the output is ROOT/NAME",
                    "--force": "batch decides (a previous attempt's outputs)",
                    "--dataset": "use the dataset column", "--preset": "use the dataset column",
                    "--config": "use the config column", "--set": "use the set column",
                    "--help": "not a job", "-h": "not a job"}
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*(/[A-Za-z0-9][A-Za-z0-9._-]*)*$")
SET_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*\.[A-Za-z_][A-Za-z0-9_.]*=.*$")
STATE_DIR = "_batch"  # ROOT/_batch: job logs, the manifest copy, markers, each job's console log
LOG_TAIL_LINES = 15


class ManifestError(Exception):
    """A bad manifest; the message names the file and line."""


class Job:
    def __init__(self, manifest, line, number, fields):
        self.manifest, self.line, self.number = manifest, line, number
        self.fields = dict(zip(COLUMNS, fields))
        self.name = self.fields["name"]
        self.command = self.fields["command"]

    def where(self):
        return f"{self.manifest}:{self.line}"

    def value(self, column):
        """The cell, or None for '-' / empty."""
        text = self.fields[column].strip()
        return None if text in ("", "-") else text

    def tokens(self, column):
        text = self.value(column)
        return shlex.split(text) if text else []

    def references(self):
        """Names of the jobs this one reads (@NAME in the dataset column or as an option value)."""
        try:
            words = [self.value("dataset") or ""] + self.tokens("options")
        except ValueError:  # bad quotes: check_job reports them
            return []
        return [w[1:] for w in words if w.startswith("@")]

    def phase(self):
        return next(p for p, commands in PHASES.items() if self.command in commands)


def fail(job, message):
    raise ManifestError(f"{job.where()}: {message}")


def read_manifest(path):
    """The jobs of a manifest, checked; ManifestError naming the file and line of the first problems."""
    path = Path(path)
    if not path.is_file():
        raise ManifestError(f"{path}: manifest not found (expected a tab-separated file, docs/batch.md)")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise ManifestError(f"{path}: cannot read the manifest: {e}") from None
    header_line, jobs, errors = None, [], []
    for line_number, raw in enumerate(text.splitlines(), start=1):
        if not raw.strip() or raw.lstrip().startswith("#"):
            continue
        fields = raw.split("\t")
        if header_line is None:
            header_line = line_number
            if [f.strip() for f in fields] != COLUMNS:
                raise ManifestError(f"{path}:{line_number}: expected the header line "
                                    f"{' TAB '.join(COLUMNS)}; got {raw!r}")
            continue
        job = Job(path, line_number, len(jobs) + 1, fields + [""] * (len(COLUMNS) - len(fields)))
        if len(fields) != len(COLUMNS):
            errors.append(f"{job.where()}: expected {len(COLUMNS)} tab-separated fields "
                          f"({', '.join(COLUMNS)}; '-' for none), got {len(fields)}")
            continue
        try:
            check_job(job)
        except ManifestError as e:
            errors.append(str(e))
        jobs.append(job)
    if header_line is None:
        raise ManifestError(f"{path}: no header line (expected: {' '.join(COLUMNS)}, tab-separated)")
    if not jobs and not errors:
        raise ManifestError(f"{path}: no job lines after the header")
    errors += check_names(jobs)
    if errors:
        raise ManifestError("\n".join(errors))
    return jobs


def check_job(job):
    name, command = job.name, job.command
    if not NAME_RE.match(name) or ".." in name.split("/"):
        fail(job, f"name '{name}': expected letters, digits, '.', '_', '-' (and '/' between folders), "
                  "starting with a letter or digit: it is the output folder ROOT/NAME")
    if command not in COMMANDS:
        fail(job, f"command '{command}': expected one of {', '.join(COMMANDS)}")
    try:
        overrides, options = job.tokens("set"), job.tokens("options")
    except ValueError as e:
        fail(job, f"set/options: {e} (quotes must be balanced)")
    dataset = job.value("dataset")
    if command == "simulate":
        if not dataset:
            fail(job, "dataset: a simulate line needs the preset to render (demo, aliasing, FILE.yaml, ...)")
        if dataset.startswith("@"):
            fail(job, f"dataset '{dataset}': a simulate line renders a preset, it reads no other job")
    elif not dataset and "--reference" not in options:
        fail(job, f"dataset: a {command} line needs a dataset folder or @NAME of a simulate line "
                  "('-' only with --reference/--query in options)")
    config = job.value("config")
    if config and not Path(config).is_file():
        fail(job, f"config '{config}': file not found (relative paths are relative to the directory "
                  f"batch runs in, {Path.cwd()})")
    for item in overrides:
        if not SET_RE.match(item):
            fail(job, f"set: '{item}' is not section.key=value")
    for option in options:
        key = option.split("=", 1)[0]
        if key in RESERVED_OPTIONS:
            fail(job, f"options: {key} is not allowed here ({RESERVED_OPTIONS[key]})")


def check_names(jobs):
    errors, by_name = [], {}
    for job in jobs:
        if job.name in by_name:
            errors.append(f"{job.where()}: name '{job.name}' already used on line {by_name[job.name].line}")
            continue
        by_name[job.name] = job
    # Every enclosing folder of a name, not only its neighbour in sorted order: 'c.x' sorts between 'c' and
    # 'c/full', and a compare 'c' writes its method folders (c/full, c/gated, ...) itself.
    for job in jobs:
        if by_name.get(job.name) is not job:
            continue
        parts = job.name.split("/")
        for k in range(1, len(parts)):
            outer = by_name.get("/".join(parts[:k]))
            if outer is not None:
                errors.append(f"{job.where()}: name '{job.name}' lies inside the output folder of '{outer.name}' "
                              f"(line {outer.line}, a {outer.command} line): one job per folder")
    for job in jobs:
        for ref in job.references():
            target = by_name.get(ref)
            if target is None:
                errors.append(f"{job.where()}: '@{ref}': no line is named '{ref}'")
            elif target.command != "simulate":
                errors.append(f"{job.where()}: '@{ref}': line {target.line} is a {target.command} line; "
                              "@NAME names the dataset a simulate line renders")
            elif job.command == "simulate":
                errors.append(f"{job.where()}: '@{ref}': simulate lines read no other job")
    return errors


def default_root(manifest):
    return Path("out") / "batch" / Path(manifest).stem


def resolve(word, root):
    return str(root / word[1:]) if word.startswith("@") else word


def job_argv(job, root, loopgate, force):
    argv = [str(loopgate), job.command]
    dataset = job.value("dataset")
    if dataset:
        argv += ["--preset" if job.command == "simulate" else "--dataset", resolve(dataset, root)]
    if job.value("config"):
        argv += ["--config", job.value("config")]
    for item in job.tokens("set"):
        argv += ["--set", item]
    argv += [resolve(w, root) for w in job.tokens("options")]
    argv += ["--out", str(root / job.name)]
    if force:
        argv.append("--force")
    return argv


def state_name(job):
    """The job's name as one file name: '/' becomes '%2F' ('%' is not allowed in names, so 'x/y' and 'x__y'
    keep distinct markers and logs)."""
    return job.name.replace("/", "%2F")


def state_file(root, kind, job, suffix):
    return root / STATE_DIR / kind / (state_name(job) + suffix)


def log_file(root, job):
    return state_file(root, "logs", job, ".log")


def folder_is_empty(folder):
    try:
        return not any(folder.iterdir())
    except FileNotFoundError:
        return True


def is_complete(job, root):
    """True when the job's outputs are there and its done marker records this very manifest line."""
    marker = state_file(root, "done", job, ".json")
    if not marker.is_file() or not (root / job.name / COMPLETION_FILE[job.command]).is_file():
        return False
    try:
        return json.loads(marker.read_text()).get("fields") == job.fields
    except (OSError, ValueError):
        return False


def now_utc():
    return datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def write_json(path, value):
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(value, indent=1) + "\n")
    tmp.replace(path)


def run_job(job, root, loopgate, jobs):
    out = root / job.name
    done = state_file(root, "done", job, ".json")
    started = state_file(root, "started", job, ".json")
    label = f"job {job.number} '{job.name}' ({job.where()}, {job.command})"
    if done.is_file():
        if is_complete(job, root):
            print(f"batch: {label}: done already ({out}), skipped", flush=True)
            return 0
        try:
            recorded = json.loads(done.read_text()).get("fields")
        except (OSError, ValueError):
            recorded = None
        if recorded is not None and recorded != job.fields and (out / COMPLETION_FILE[job.command]).is_file():
            print(f"batch: error: {job.where()}: '{job.name}' was done in {out} by a different manifest line "
                  f"({recorded}); give the changed line a new name, or remove {out} and {done} to redo it",
                  file=sys.stderr, flush=True)
            return 2
        done.unlink()  # the outputs were removed: redo
    by_name = {j.name: j for j in jobs}
    for ref in job.references():
        if not is_complete(by_name[ref], root):
            print(f"batch: error: {job.where()}: '{job.name}' reads @{ref}, which is not rendered yet "
                  f"({root / ref / 'simulation.json'} missing): run the simulate lines first "
                  "(batch.sh does; with Slurm, --dependency=afterok on the simulate array)",
                  file=sys.stderr, flush=True)
            return 1
    # A previous attempt of this job (started, never done) left outputs: replace them, but only when the
    # folder was absent or empty before batch first started the job. A folder that already held something
    # (another run's outputs) stays so on every attempt: loopgate's own refusal names what it found.
    previous = None
    if started.is_file():
        try:
            previous = json.loads(started.read_text())
        except (OSError, ValueError):
            previous = {}
    owned = previous.get("folder_was_empty_at_first_start") is True if previous is not None \
        else folder_is_empty(out)
    force = owned and previous is not None and out.exists()
    if not owned:
        print(f"batch: {label}: {out} held files before batch first started this job: they are not replaced "
              "(no --force); remove them, or give the line another name", flush=True)
    argv = job_argv(job, root, loopgate, force)
    log = log_file(root, job)
    log.parent.mkdir(parents=True, exist_ok=True)
    write_json(started, {"fields": job.fields, "argv": argv, "start_time_utc": now_utc(),
                         "host": socket.gethostname(), "pid": os.getpid(),
                         "folder_was_empty_at_first_start": owned})
    print(f"batch: {label}: {shlex.join(argv)}", flush=True)
    t0 = time.monotonic()
    with open(log, "a") as f:
        f.write(f"=== {now_utc()} {socket.gethostname()}: {shlex.join(argv)}\n")
        f.flush()
        try:
            child = subprocess.Popen(argv, stdout=f, stderr=subprocess.STDOUT)
        except OSError as e:
            print(f"batch: error: {label}: cannot start {argv[0]}: {e} (build it, or pass --loopgate BIN)",
                  file=sys.stderr, flush=True)
            return 1
        # A stop (parallel's SIGTERM, Ctrl-C) goes to loopgate, which writes its outputs and exits; we wait.
        for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
            signal.signal(sig, lambda number, _frame: child.send_signal(number))
        status = child.wait()
    seconds = time.monotonic() - t0
    if status == 0:
        write_json(done, {"fields": job.fields, "argv": argv, "end_time_utc": now_utc(), "seconds": seconds,
                          "host": socket.gethostname()})
        started.unlink(missing_ok=True)
        print(f"batch: {label}: ok in {seconds:.1f} s ({out})", flush=True)
        return 0
    reason = f"exit status {status}" if status > 0 else f"signal {-status}"
    attempt = log.read_text(errors="replace").split("\n=== ")[-1].splitlines()
    errors = [line for line in attempt if "[error]" in line or "[critical]" in line]
    tail = (errors or attempt)[-LOG_TAIL_LINES:]  # loopgate's errors, else the end of its console
    print(f"batch: FAILED {label}: {reason} after {seconds:.1f} s; log {log}:\n  " + "\n  ".join(tail),
          file=sys.stderr, flush=True)
    return status if 0 < status < 256 else 1


def read_joblog(path):
    """{seq: (exit, signal, job number)} of the last entry per seq of a GNU parallel --joblog."""
    entries = {}
    if not path.is_file():
        return entries
    with open(path, newline="") as f:
        for row in csv.reader(f, delimiter="\t"):
            if not row or row[0] == "Seq" or len(row) < 9:
                continue
            try:
                entries[int(row[0])] = (int(row[6]), int(row[7]), int(row[8].split()[-1]))
            except (ValueError, IndexError):
                continue
    return entries


def joblog_path(root, phase):
    return root / STATE_DIR / f"joblog-{phase}.tsv"


def prepare(manifest, jobs, root):
    """State folder and manifest copy; a job log no longer true of the outputs is set aside (GNU parallel's
    --resume-failed trusts it by sequence number alone)."""
    state = root / STATE_DIR
    state.mkdir(parents=True, exist_ok=True)
    copy = state / "manifest.tsv"
    text = Path(manifest).read_text()
    stale = []
    if copy.is_file() and copy.read_text() != text:
        stale = [(p, "the manifest changed since it was written") for p in PHASES]
    else:
        by_number = {j.number: j for j in jobs}
        for phase in PHASES:
            for exit_status, sig, number in read_joblog(joblog_path(root, phase)).values():
                job = by_number.get(number)
                if exit_status == 0 and sig == 0 and (job is None or not is_complete(job, root)):
                    what = f"'{job.name}'" if job else f"job {number}"
                    stale.append((phase, f"{what} finished there but its outputs are gone"))
                    break
    for phase, why in stale:
        log = joblog_path(root, phase)
        if log.is_file():
            old = log.with_name(f"{log.stem}.{datetime.datetime.now():%Y%m%dT%H%M%S}.tsv")
            log.replace(old)
            print(f"batch: {log}: {why}: kept as {old.name}, starting a new one (finished jobs whose lines "
                  "are unchanged are still skipped)", file=sys.stderr)
    copy.write_text(text)


def report(jobs, root, phase):
    by_number = {j.number: j for j in jobs}
    entries = read_joblog(joblog_path(root, phase))
    # A failed entry of a job that is complete now (done by a later attempt, or by another batch on the same
    # root before it was locked out) is no failure: the outputs and the done marker are the truth.
    failed = [(by_number[n], e, s) for e, s, n in entries.values()
              if (e != 0 or s != 0) and n in by_number and not is_complete(by_number[n], root)]
    for job, exit_status, sig in sorted(failed, key=lambda f: f[0].number):
        reason = f"signal {sig}" if sig else f"exit status {exit_status}"
        log = log_file(root, job)
        print(f"batch: FAILED {job.where()}: job {job.number} '{job.name}' ({job.command}): {reason}; "
              f"log {log}", file=sys.stderr)
    missing = [j for j in jobs if j.phase() == phase and j.number not in {n for _, _, n in entries.values()}]
    for job in missing:
        print(f"batch: NOT FINISHED {job.where()}: job {job.number} '{job.name}' has no entry in "
              f"{joblog_path(root, phase)} (interrupted, or GNU parallel stopped before it)", file=sys.stderr)
    return 1 if failed or missing else 0


def ranges(numbers):
    out, start = [], None
    for k, n in enumerate(numbers):
        if start is None:
            start = n
        if k + 1 == len(numbers) or numbers[k + 1] != n + 1:
            out.append(str(start) if start == n else f"{start}-{n}")
            start = None
    return ",".join(out)


def main():
    parser = argparse.ArgumentParser(description="loopgate batch manifest: check, list, run one job.")
    sub = parser.add_subparsers(dest="what", required=True)
    p = sub.add_parser("check")
    p.add_argument("manifest")
    p = sub.add_parser("indices")
    p.add_argument("manifest")
    p.add_argument("phase", choices=list(PHASES))
    p.add_argument("--ranges", action="store_true")
    for name in ("prepare", "report", "job"):
        p = sub.add_parser(name)
        p.add_argument("--out", type=Path, help="ROOT (default out/batch/<manifest name>)")
        p.add_argument("manifest")
        if name == "report":
            p.add_argument("phase", choices=list(PHASES))
        if name == "job":
            p.add_argument("--loopgate", type=Path,
                           default=Path(os.environ.get("LOOPGATE", Path(__file__).resolve().parent.parent
                                                       / "build" / "release" / "loopgate")))
            p.add_argument("number", help="job number: 1 = the first job line (the Slurm array index)")
    args = parser.parse_args()
    try:
        jobs = read_manifest(args.manifest)
    except ManifestError as e:
        print(f"batch: error: {e}", file=sys.stderr)
        return 2
    root = getattr(args, "out", None) or default_root(args.manifest)
    if args.what == "check":
        counts = {p: sum(j.phase() == p for j in jobs) for p in PHASES}
        print(f"{args.manifest}: {len(jobs)} jobs ({counts['simulate']} simulate, "
              f"{counts['runs']} run/compare)")
        return 0
    if args.what == "indices":
        numbers = [j.number for j in jobs if j.phase() == args.phase]
        print(ranges(numbers) if args.ranges else "\n".join(map(str, numbers)))
        return 0
    if args.what == "prepare":
        prepare(args.manifest, jobs, root)
        return 0
    if args.what == "report":
        return report(jobs, root, args.phase)
    if not args.number.isdigit() or not 1 <= int(args.number) <= len(jobs):
        print(f"batch: error: {args.manifest}: job number '{args.number}': expected 1..{len(jobs)} "
              "(job lines in order; header, comments and blank lines not counted)", file=sys.stderr)
        return 2
    return run_job(jobs[int(args.number) - 1], root, args.loopgate, jobs)


if __name__ == "__main__":
    sys.exit(main())
