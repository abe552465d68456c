#!/usr/bin/env bash
# Runs a loopgate batch manifest (docs/batch.md) with GNU parallel: first every simulate line (the datasets),
# then every run and compare line, -j N at a time, each job's console in ROOT/_batch/logs/NAME.log.
#
#   scripts/batch.sh MANIFEST [-j N] [--out ROOT] [--loopgate BIN]
#   scripts/batch.sh MANIFEST --slurm-array simulate|runs   (the job numbers of a phase, for sbatch --array)
#
# ROOT defaults to out/batch/<manifest name>. A second batch.sh on the same ROOT resumes: GNU parallel's
# --resume-failed skips what its job log (ROOT/_batch/joblog-<phase>.tsv) says succeeded and retries what
# failed, and a job whose done marker records the same manifest line is skipped by the job itself (so a
# changed manifest, or Slurm, skips finished runs too). A batch.sh on a ROOT where another is running is refused.
# Exit status: 0 every job ok, 1 a job failed (each failed line named as MANIFEST:LINE), 2 a bad manifest,
# usage, or a ROOT in use.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
python=/usr/bin/python3
usage="usage: scripts/batch.sh MANIFEST [-j N] [--out ROOT] [--loopgate BIN]
       scripts/batch.sh MANIFEST --slurm-array simulate|runs"

manifest="" jobs="" root="" loopgate="" slurm_phase=""
while (($#)); do
  case "$1" in
    -j | --jobs)
      [[ $# -ge 2 ]] || { echo "batch: $1 needs a value; $usage" >&2; exit 2; }
      jobs="$2"; shift 2 ;;
    -j*) jobs="${1#-j}"; shift ;;
    --out)
      [[ $# -ge 2 ]] || { echo "batch: --out needs a folder; $usage" >&2; exit 2; }
      root="$2"; shift 2 ;;
    --loopgate)
      [[ $# -ge 2 ]] || { echo "batch: --loopgate needs a path; $usage" >&2; exit 2; }
      loopgate="$2"; shift 2 ;;
    --slurm-array)
      [[ $# -ge 2 ]] || { echo "batch: --slurm-array needs simulate or runs; $usage" >&2; exit 2; }
      slurm_phase="$2"; shift 2 ;;
    -h | --help) echo "$usage"; exit 0 ;;
    -*) echo "batch: unknown option $1; $usage" >&2; exit 2 ;;
    *)
      [[ -z "$manifest" ]] || { echo "batch: one MANIFEST only (got $manifest and $1); $usage" >&2; exit 2; }
      manifest="$1"; shift ;;
  esac
done
[[ -n "$manifest" ]] || { echo "batch: no MANIFEST; $usage" >&2; exit 2; }

if [[ -n "$slurm_phase" ]]; then
  exec "$python" "$here/batch.py" indices "$manifest" "$slurm_phase" --ranges
fi

# Each loopgate run uses run.threads (2) worker threads: by default one job per two cores.
if [[ -z "$jobs" ]]; then
  jobs=$(( $(nproc) / 2 )); ((jobs >= 1)) || jobs=1
fi
if ! [[ "$jobs" =~ ^[0-9]+$ ]] || ((jobs < 1 || jobs > 1024)); then
  echo "batch: -j '$jobs': expected a whole number of jobs in 1..1024" >&2
  exit 2
fi
# moreutils ships another program named parallel; the job log and --resume-failed are GNU parallel's.
if ! command -v parallel >/dev/null || ! parallel --version 2>/dev/null | grep -q "GNU parallel"; then
  echo "batch: GNU parallel not found (Debian package 'parallel'; scripts/setup.sh installs it)" >&2
  exit 2
fi

"$python" "$here/batch.py" check "$manifest" >&2 || exit 2
if [[ -z "$root" ]]; then
  name="$(basename "$manifest")"
  root="out/batch/${name%.*}" # as batch.py's default (Path.stem), which the Slurm template uses
fi
mkdir -p "$root/_batch"
root="$(cd "$root" && pwd)"
# One batch.sh per root: two at once would run the same jobs into the same folders and write one job log.
# The lock is held by this shell and its children (GNU parallel, the jobs) and released when they end.
exec 9>>"$root/_batch/lock"
if ! flock -n 9; then
  holder="$(cat "$root/_batch/lock.pid" 2>/dev/null || true)"
  echo "batch: $root is in use by another batch.sh${holder:+ (pid $holder)}: wait for it to end, or use" \
    "another --out" >&2
  exit 2
fi
echo $$ >"$root/_batch/lock.pid"
manifest="$(cd "$(dirname "$manifest")" && pwd)/$(basename "$manifest")"
job_args=(--out "$root")
[[ -z "$loopgate" ]] || job_args+=(--loopgate "$(realpath "$loopgate")")
"$python" "$here/batch.py" prepare --out "$root" "$manifest"

start=$SECONDS
for phase in simulate runs; do
  mapfile -t numbers < <("$python" "$here/batch.py" indices "$manifest" "$phase")
  [[ -n "${numbers[0]:-}" ]] || continue
  echo "batch: $phase: ${#numbers[@]} job(s), $jobs at a time (job log $root/_batch/joblog-$phase.tsv)" >&2
  # The job number is the last word of each command: batch.py reads it back from the job log.
  # -q: the words are passed as they are (paths with spaces), not re-read by a shell.
  parallel -q --joblog "$root/_batch/joblog-$phase.tsv" --resume-failed -j "$jobs" \
    "$python" "$here/batch.py" job "${job_args[@]}" "$manifest" {} ::: "${numbers[@]}" || true
  if ! "$python" "$here/batch.py" report --out "$root" "$manifest" "$phase"; then
    if [[ "$phase" == simulate ]]; then
      echo "batch: the run and compare lines were not started (they read the rendered datasets)" >&2
    fi
    echo "batch: failed after $((SECONDS - start)) s; fix the lines named above and run the same command" \
      "again: finished jobs are not redone" >&2
    exit 1
  fi
done
echo "batch: every job of $manifest done in $((SECONDS - start)) s; outputs in $root" >&2
echo "batch: the table: build/release/loopgate aggregate $root" >&2
