#!/usr/bin/env bash
# Submit a sharded octocd run to Slurm (docs/cluster.md): an array job of N shards
# (scripts/slurm/shard.sbatch, one shard per task) and a join (scripts/slurm/join.sbatch)
# that runs after every task has ended (--dependency=afterany:<array>), checks that every
# shard finished whole (else it fails naming each shard that did not) and merges them.
#
# Usage: scripts/slurm/submit.sh sweep SWEEP [options] [-- bench options]
#        scripts/slurm/submit.sh validate TRACE.h5 [options] [-- validate options]
#   sweep SWEEP      `octocd bench SWEEP --shard i/N` per task (a named sweep or a sweep
#                    file); the join: `octocd report` of the shards into RUN/report/
#                    (index.html, report.md, csv/)
#   validate TRACE   `octocd validate --trace-in TRACE --shard i/N` per task; the join:
#                    `octocd validate --merge` into RUN/verdict.json, verdict.xml (JUnit)
#                    and verdict.txt (the table)
# Options:
#   --octocd PATH    the octocd binary the jobs run (default: build/octocd of this source
#                    tree when present, else octocd on PATH); it must be at this path on the
#                    compute nodes (a shared file system)
#   --run-dir DIR    the run folder, new or empty, on a file system the nodes share (default:
#                    slurm-runs/MODE-YYYYmmdd-HHMMSS): shards/ (the shards' outputs), status/
#                    (exit statuses), logs/ (shard-i.log, join.log), the merged outputs
#   --shards N       array tasks, shard i/N for i = 0..N-1 (default 4; 1..10000)
#   --partition P    the array's partition: a CPU partition for the cpu, bullet, mujoco and
#                    ode engines, a GPU partition (with --gpus 1) for cuda (default: the
#                    cluster's default partition)
#   --gpus G         GPUs per task (--gres=gpu:G; default none)
#   --cpus C         CPUs per task (default 1); the task's OMP_NUM_THREADS
#   --time T         time limit per task (sbatch --time; default: the partition's)
#   --max-running K  at most K tasks at once (--array=0-<N-1>%K)
#   --join-partition P  the join's partition (default: --partition; it needs no GPU)
#   --after JOB      start the array after JOB ended with exit 0 (afterok), e.g. the job
#                    writing TRACE (which then need not exist yet)
#   --sbatch OPT     one more sbatch option for both jobs, repeatable (--sbatch=--account=A)
#   --merge-arg ARG  one more argument of the join's `validate --merge` (e.g. --expect FILE)
#                    or `report` (e.g. --baseline FILE), repeatable
#   --wait           wait for the join and exit with its status (below)
#   -- ARG ...       arguments for every shard's octocd bench / validate (e.g. --engines cpu,
#                    --every 5, --data-dir DIR); each shard gets the same
# Prints one line each: "run DIR", "array JOBID", "join JOBID" (with --wait, then the join's
# outcome). Exit 0 submitted (with --wait: the join's status: 0 merged and passed; 1 a shard
# did not finish whole, named in RUN/logs/join.log and here, or the join itself did not
# finish; validate 3 a row fails; report 4 the gate fails), 2 bad usage or input (nothing
# submitted), 1 sbatch refused a job (an array already submitted is cancelled).
set -uo pipefail

usage() { sed -n '2,/^set -uo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2; exit "$1"; }
die() { echo "submit.sh: $*" >&2; exit 2; }

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
[ $# -ge 1 ] || usage 2
case "$1" in
  -h|--help) usage 0 ;;
  sweep|validate) mode=$1 ;;
  *) die "mode '$1'; allowed: sweep SWEEP, validate TRACE (--help)" ;;
esac
[ $# -ge 2 ] || die "$mode needs its $( [ "$mode" = sweep ] && echo SWEEP || echo TRACE )"
target=$2
shift 2

octocd="" run="" shards=4 partition="" gpus="" cpus=1 time_limit="" max_running="" join_partition=""
after="" wait=0
sbatch_extra=() merge_args=() extra=()
need() { [ $# -ge 2 ] && [ -n "$2" ] || die "$1 needs a value"; }
while [ $# -gt 0 ]; do
  case "$1" in
    --octocd) need "$@"; octocd=$2; shift 2 ;;
    --run-dir) need "$@"; run=$2; shift 2 ;;
    --shards) need "$@"; shards=$2; shift 2 ;;
    --partition) need "$@"; partition=$2; shift 2 ;;
    --gpus) need "$@"; gpus=$2; shift 2 ;;
    --cpus) need "$@"; cpus=$2; shift 2 ;;
    --time) need "$@"; time_limit=$2; shift 2 ;;
    --max-running) need "$@"; max_running=$2; shift 2 ;;
    --join-partition) need "$@"; join_partition=$2; shift 2 ;;
    --after) need "$@"; after=$2; shift 2 ;;
    --sbatch) need "$@"; sbatch_extra+=("$2"); shift 2 ;;
    --sbatch=*) sbatch_extra+=("${1#--sbatch=}"); shift ;;
    --merge-arg) [ $# -ge 2 ] || die "--merge-arg needs a value"; merge_args+=("$2"); shift 2 ;;
    --merge-arg=*) merge_args+=("${1#--merge-arg=}"); shift ;;
    --wait) wait=1; shift ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) usage 0 ;;
    *) die "option '$1'; allowed: --octocd, --run-dir, --shards, --partition, --gpus, --cpus, --time, --max-running, --join-partition, --after, --sbatch, --merge-arg, --wait, -- (--help)" ;;
  esac
done

posint() { [[ "$2" =~ ^[1-9][0-9]*$ ]] && [ "${#2}" -le 6 ] || die "$1 '$2'; allowed: an integer >= 1"; }
posint --shards "$shards"
[ "$shards" -le 10000 ] || die "--shards $shards; allowed: 1..10000"
posint --cpus "$cpus"
[ -z "$gpus" ] || posint --gpus "$gpus"
[ -z "$max_running" ] || posint --max-running "$max_running"
[ -z "$after" ] || [[ "$after" =~ ^[0-9]+(_[0-9]+)?$ ]] || die "--after '$after'; allowed: a job id"
command -v sbatch >/dev/null 2>&1 || die "sbatch not found: run this on a Slurm submit host"

if [ -z "$octocd" ]; then
  if [ -x "$root/build/octocd" ]; then octocd="$root/build/octocd"; else octocd="$(command -v octocd || true)"; fi
  [ -n "$octocd" ] || die "no octocd: neither $root/build/octocd nor octocd on PATH; give --octocd PATH"
fi
[ -x "$octocd" ] && [ -f "$octocd" ] || die "--octocd '$octocd': not an executable file"
octocd="$(cd "$(dirname "$octocd")" && pwd)/$(basename "$octocd")"

abs() { case "$1" in /*) echo "$1" ;; *) echo "$PWD/$1" ;; esac; }
if [ "$mode" = validate ]; then
  target="$(abs "$target")"
  [ -n "$after" ] || [ -r "$target" ] || die "TRACE '$target': not readable (with --after JOB it may be written by JOB)"
elif [ -e "$target" ] || [[ "$target" == */* ]] || [[ "$target" == *.json ]]; then
  [ -r "$target" ] || die "SWEEP '$target': no such sweep file (a named sweep is a plain name: octocd bench --list)"
  target="$(abs "$target")"
fi

[ -n "$run" ] || run="slurm-runs/$mode-$(date +%Y%m%d-%H%M%S)"
run="$(abs "$run")"
if [ -e "$run" ] && [ -n "$(ls -A "$run" 2>/dev/null)" ]; then
  die "--run-dir '$run': not empty; allowed: a new or empty folder (a run's shards must not meet another run's)"
fi
# sbatch reads --output as a filename pattern: % starts a replacement (%j, %a, ...) and a
# backslash turns every replacement off (the shards' logs would then share one file). A %
# of the folder's name is written %% (sbatch's escape); a backslash is refused.
case "$run" in *\\*) die "--run-dir '$run': holds a backslash, which turns off sbatch's --output patterns; allowed: a folder name without \\" ;; esac
logs_pattern="${run//%/%%}/logs"
mkdir -p "$run/shards" "$run/status" "$run/logs" || die "--run-dir '$run': cannot create it"

common=(--parsable)
[ ${#sbatch_extra[@]} -eq 0 ] || common+=("${sbatch_extra[@]}")
array_opts=("${common[@]}" --job-name="octocd-$mode" --array="0-$((shards - 1))${max_running:+%$max_running}"
            --cpus-per-task="$cpus" --output="$logs_pattern/shard-%a.log")
[ -z "$partition" ] || array_opts+=(--partition="$partition")
[ -z "$gpus" ] || array_opts+=(--gres="gpu:$gpus")
[ -z "$time_limit" ] || array_opts+=(--time="$time_limit")
# A JOB that fails cancels the array (else its tasks would wait forever); the join then names
# every shard as not finished.
[ -z "$after" ] || array_opts+=(--dependency="afterok:$after" --kill-on-invalid-dep=yes)
join_partition=${join_partition:-$partition}

{
  echo "mode=$mode"
  echo "target=$target"
  echo "shards=$shards"
  echo "octocd=$octocd"
  printf 'shard_args='; printf ' %q' "${extra[@]+"${extra[@]}"}"; echo
  printf 'merge_args='; printf ' %q' "${merge_args[@]+"${merge_args[@]}"}"; echo
  echo "submitted=$(date -u +%FT%TZ) from $(hostname)"
} >"$run/run.txt"

array_id=$(sbatch "${array_opts[@]}" "$here/shard.sbatch" "$mode" "$run" "$shards" "$octocd" "$target" \
  "${extra[@]+"${extra[@]}"}") || { echo "submit.sh: sbatch refused the array (above); nothing submitted" >&2; exit 1; }
array_id=${array_id%%;*}
echo "array_job=$array_id" >>"$run/run.txt"
echo "run $run"
echo "array $array_id"

join_opts=("${common[@]}" --job-name="octocd-$mode-join" --dependency="afterany:$array_id"
           --output="$logs_pattern/join.log")
[ -z "$join_partition" ] || join_opts+=(--partition="$join_partition")
join_cmd=("$here/join.sbatch" "$mode" "$run" "$shards" "$array_id" "$octocd" "${merge_args[@]+"${merge_args[@]}"}")
refused() {
  echo "submit.sh: sbatch refused the join (above); cancelling the array $array_id" >&2
  scancel "$array_id" 2>/dev/null
  exit 1
}
if [ "$wait" = 0 ]; then
  join_id=$(sbatch "${join_opts[@]}" "${join_cmd[@]}") || refused
  join_id=${join_id%%;*}
  echo "join_job=$join_id" >>"$run/run.txt"
  echo "join $join_id"
  exit 0
fi

# --wait: sbatch --wait prints the join's id at once (line-buffered), then waits. Its own
# exit status is the job's only while Slurm still knows the job (MinJobAge), so the join's
# status is read from RUN/status/join.rc, which join.sbatch writes last.
exec 3< <(sbatch --wait "${join_opts[@]}" "${join_cmd[@]}"; echo "sbatch-exit $?")
IFS= read -r line <&3
case "$line" in
  "sbatch-exit "*) refused ;;
esac
join_id=${line%%;*}
echo "join_job=$join_id" >>"$run/run.txt"
echo "join $join_id"
while IFS= read -r line <&3; do
  case "$line" in "sbatch-exit "*) break ;; *) echo "$line" ;; esac
done
exec 3<&-
if [ ! -f "$run/status/join.rc" ]; then
  echo "join $join_id did not finish (cancelled, past its time limit or its node lost): no $run/status/join.rc; its log: $run/logs/join.log" >&2
  exit 1
fi
rc=$(cat "$run/status/join.rc")
if [ "$rc" = 0 ]; then
  echo "join $join_id: exit 0 ($mode merged: $( [ "$mode" = sweep ] && echo "$run/report/index.html" || echo "$run/verdict.json"))"
else
  echo "join $join_id: exit $rc; its log $run/logs/join.log:" >&2
  grep -v '^[[:space:]]*$' "$run/logs/join.log" | tail -n 20 | sed 's/^/  /' >&2
fi
exit "$rc"
