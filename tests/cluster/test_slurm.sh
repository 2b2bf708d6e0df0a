#!/usr/bin/env bash
# ctest cluster.slurm: scripts/slurm/ on a real single-node Slurm (docs/cluster.md).
# Starts munged, slurmctld and slurmd of their own (a munge key, sockets, ports, state and
# logs in a temporary folder; the host's own Slurm and munge, if any, untouched), waits for the
# node to be idle, then through scripts/slurm/submit.sh ... --wait:
#   1. a 4-shard sweep (tests/cluster/sweep-small.json: 6 points on the cpu engine, 2
#      repetitions): the join's report holds the same points, repetitions and per-frame
#      counts (pairs, contacts, penetration: every column but the timings) as the report of
#      the same sweep run unsharded;
#   2. a 4-shard validation of a Bullet trace with every contact normal flipped (rows fail,
#      exit 3 in every shard): the merged verdict equals the unsharded run's, row by row;
#   3. the same validation with shard 2 held on a FIFO until scancel cancels its array task:
#      the join fails (exit 1) naming shard 2/4 and merges nothing; `validate --merge` of the
#      three other shards refuses the missing one (exit 2, naming its frames);
#   4. the join run by hand on copies of the sweep's run folder: a shard without exit status,
#      with a bad one, or with an unfinished result file makes it fail naming that shard.
# Every daemon is stopped on exit (trap), on failure too (the folder is then kept, its logs'
# tails printed). Exit 0 pass, 1 fail, 77 skipped with the reason (not root, no Slurm or munge
# binaries, no h5py).
# Usage: test_slurm.sh OCTOCD SOURCE_DIR
set -uo pipefail

octocd=${1:?usage: test_slurm.sh OCTOCD SOURCE_DIR}
src=${2:?usage: test_slurm.sh OCTOCD SOURCE_DIR}
submit="$src/scripts/slurm/submit.sh"
join="$src/scripts/slurm/join.sbatch"
export PATH="$PATH:/usr/sbin:/sbin"
py=/usr/bin/python3
[ -x "$py" ] || py=$(command -v python3 || echo python3)

skip() { echo "SKIP: $*"; exit 77; }
[ "$(id -u)" = 0 ] || skip "not root: slurmd runs jobs as their user only when started as root"
for b in munged slurmctld slurmd sbatch squeue sinfo scancel scontrol; do
  command -v "$b" >/dev/null 2>&1 || skip "no $b (Debian packages slurm-wlm and munge)"
done
"$py" -c 'import h5py' 2>/dev/null || skip "no h5py for $py (python3-h5py): the test plants flipped normals with it"

t_start=$SECONDS
tmp=$(mktemp -d /tmp/octocd-slurm.XXXXXX) || exit 1
chmod 755 "$tmp"  # munged refuses a socket folder that others cannot search
host=$(hostname -s)
munge_sock="$tmp/munge.socket"
ctld_pid="" slurmd_pid="" munged_up=0 failed=0

fail() { echo "FAIL: $*"; failed=1; exit 1; }
note() { echo "[$((SECONDS - t_start)) s] $*"; }

# Polls CONDITION (a command) until it holds; fails after DEADLINE seconds naming WHAT.
wait_for() {
  local deadline=$1 what=$2
  shift 2
  local end=$((SECONDS + deadline))
  until "$@"; do
    [ "$SECONDS" -lt "$end" ] || fail "waited $deadline s for $what"
    sleep 0.1
  done
}

stop_pid() {  # TERM, wait up to 20 s, then KILL
  local pid=$1
  [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null || return 0
  kill -TERM "$pid" 2>/dev/null
  local end=$((SECONDS + 20))
  while kill -0 "$pid" 2>/dev/null && [ "$SECONDS" -lt "$end" ]; do sleep 0.1; done
  kill -KILL "$pid" 2>/dev/null
  wait "$pid" 2>/dev/null
}

queue_empty() { [ -z "$(squeue -h -o %i 2>/dev/null)" ]; }

cleanup() {
  local rc=$?
  [ "$failed" = 1 ] && rc=1
  trap - EXIT
  if [ -n "$ctld_pid" ] && kill -0 "$ctld_pid" 2>/dev/null; then
    # Jobs first (their steps' processes end with them), then the daemons.
    ids=$(squeue -h -o %i 2>/dev/null)
    [ -z "$ids" ] || scancel $ids 2>/dev/null
    local end=$((SECONDS + 30))
    while ! queue_empty && [ "$SECONDS" -lt "$end" ]; do sleep 0.1; done
  fi
  stop_pid "$slurmd_pid"
  stop_pid "$ctld_pid"
  [ "$munged_up" = 1 ] && munged --stop --socket="$munge_sock" >/dev/null 2>&1
  if [ "$rc" = 0 ]; then
    rm -rf "$tmp"
  else
    echo "kept $tmp; the logs' last lines:"
    for f in "$tmp"/log/*.log "$tmp"/*/logs/*.log; do
      [ -f "$f" ] || continue
      echo "--- $f"
      tail -n 15 "$f"
    done
  fi
  note "done, exit $rc"
  exit "$rc"
}
trap cleanup EXIT
trap 'exit 1' INT TERM

# ---- munge: its own key, socket, pid, log and seed files ------------------------------
mkdir -p "$tmp/log" "$tmp/state" "$tmp/spool" || exit 1
if command -v mungekey >/dev/null 2>&1; then
  mungekey --create --keyfile="$tmp/munge.key" >/dev/null || fail "mungekey"
else
  head -c 1024 /dev/urandom >"$tmp/munge.key" || fail "munge key"
fi
chmod 600 "$tmp/munge.key"
munged --socket="$munge_sock" --key-file="$tmp/munge.key" --pid-file="$tmp/munged.pid" \
  --log-file="$tmp/log/munged.log" --seed-file="$tmp/munged.seed" \
  || skip "Slurm cannot start here: munged did not start: $(tail -n 3 "$tmp/log/munged.log" 2>/dev/null)"
munged_up=1  # munged returns once its socket is up

# ---- slurm.conf: this host as controller and only node -----------------------------------
# Two free TCP ports (bound then released: another process may take them in between, rarely).
read -r ctld_port slurmd_port < <("$py" -c '
import socket
s = [socket.socket() for _ in range(2)]
for x in s: x.bind(("127.0.0.1", 0))
print(*[x.getsockname()[1] for x in s])') || fail "no free ports"
# The node's real sockets, cores, threads and memory (slurmd -C), else the CPU count.
node=$(slurmd -C 2>/dev/null | grep -m 1 '^NodeName=' | sed "s/^NodeName=[^ ]*//")
[ -n "$node" ] || node=" CPUs=$(nproc)"
cat >"$tmp/slurm.conf" <<EOF
# The test's cluster (tests/cluster/test_slurm.sh): no cgroups (proctrack/linuxproc,
# task/none, no accounting), so slurmd runs in a container without cgroup access.
ClusterName=octocdtest
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$munge_sock
CredType=cred/munge
StateSaveLocation=$tmp/state
SlurmdSpoolDir=$tmp/spool
SlurmctldPidFile=$tmp/slurmctld.pid
SlurmdPidFile=$tmp/slurmd.pid
SlurmctldLogFile=$tmp/log/slurmctld.log
SlurmdLogFile=$tmp/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/builtin
# Schedule at once after a submission or a job's end (default: batched over 3 s).
SchedulerParameters=batch_sched_delay=0
# A finished job is kept 4 s: sbatch --wait then polls every 2 s (it polls more slowly as
# MinJobAge grows) and still finds it.
MinJobAge=4
KillWait=5
ReturnToService=2
MpiDefault=none
MailProg=/bin/true
SlurmctldDebug=info
SlurmdDebug=info
NodeName=$host NodeAddr=127.0.0.1$node State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
# slurmd 22.05 loads a cgroup plugin whatever the plugins above use (autodetect by default:
# cgroup/v2 on a cgroup v2 host, which then wants systemd over dbus, or stops on a mixed
# hierarchy; a container has neither systemd nor a writable /sys/fs/cgroup). cgroup/v1's
# init touches nothing: the cgroups are created only for a plugin that asks (proctrack/cgroup,
# task/cgroup, jobacct_gather/cgroup), and none here does.
echo "CgroupPlugin=cgroup/v1" >"$tmp/cgroup.conf"
export SLURM_CONF="$tmp/slurm.conf"
# Nothing of an enclosing Slurm job (were the test run inside one) reaches these commands.
for v in $(compgen -e | grep '^SLURM_' | grep -v '^SLURM_CONF$'); do unset "$v"; done

# ---- slurmctld and slurmd: children of this script (-D), so the trap can wait for them ----
slurmctld -D -f "$SLURM_CONF" >>"$tmp/log/slurmctld.out" 2>&1 &
ctld_pid=$!
slurmd -D -f "$SLURM_CONF" -N "$host" >>"$tmp/log/slurmd.out" 2>&1 &
slurmd_pid=$!
# The daemons not coming up is "Slurm cannot start here" (a skip naming why, with their
# logs); what the jobs do once it is up is the test.
node_idle() {
  kill -0 "$ctld_pid" 2>/dev/null || skip "Slurm cannot start here: slurmctld exited: $(tail -n 5 "$tmp/log/slurmctld.log" "$tmp/log/slurmctld.out" 2>/dev/null)"
  kill -0 "$slurmd_pid" 2>/dev/null || skip "Slurm cannot start here: slurmd exited: $(tail -n 5 "$tmp/log/slurmd.log" "$tmp/log/slurmd.out" 2>/dev/null)"
  [ "$(sinfo -h -n "$host" -o %T 2>/dev/null)" = idle ]
}
idle_end=$((SECONDS + 60))
until node_idle; do
  [ "$SECONDS" -lt "$idle_end" ] || skip "Slurm cannot start here: node $host not idle within 60 s (sinfo: $(sinfo -h -o '%T %E' 2>&1 | head -n 2)); slurmd log: $(tail -n 5 "$tmp/log/slurmd.log" 2>/dev/null)"
  sleep 0.1
done
note "Slurm up: node $host$node, ports $ctld_port/$slurmd_port"

export OMP_NUM_THREADS=1
mkdir -p "$tmp/whole" || exit 1

# ---- 1. sharded sweep == unsharded sweep ------------------------------------------------
sweep="$src/tests/cluster/sweep-small.json"
"$octocd" bench "$sweep" -o "$tmp/whole/sweep.json" --quiet || fail "unsharded bench exited $?"
"$octocd" report "$tmp/whole/sweep.json" -o "$tmp/whole/report" --csv "$tmp/whole/report/csv" >/dev/null \
  || fail "report of the unsharded sweep exited $?"
note "unsharded sweep and its report"
"$submit" sweep "$sweep" --octocd "$octocd" --run-dir "$tmp/sweep" --shards 4 --partition debug --wait \
  >"$tmp/sweep.out" 2>&1
rc=$?
cat "$tmp/sweep.out"
[ "$rc" = 0 ] || fail "submit.sh sweep --wait exited $rc"
grep -q '^array [0-9]' "$tmp/sweep.out" && grep -q '^join [0-9]' "$tmp/sweep.out" || fail "submit.sh printed no job ids"
"$py" - "$tmp/whole/report" "$tmp/sweep/report" "$tmp/sweep/shards" <<'PY' || fail "the sharded sweep's report differs"
import csv, json, pathlib, sys
whole, sharded, shards = (pathlib.Path(p) for p in sys.argv[1:])
def rows(report):
    with open(report / "csv" / "cluster-small.csv") as f:
        table = list(csv.DictReader(f))
    timing = ("ms", "steps_per_s", "wall_s", "setup_")  # measured times differ from run to run
    keep = [c for c in table[0] if not any(t in c for t in timing)]
    return keep, sorted(tuple(r[c] for c in keep) for r in table)
kw, w = rows(whole)
ks, s = rows(sharded)
assert kw == ks, f"columns differ: {kw} vs {ks}"
points = {r[kw.index("point")] for r in w}
reps = [r for r in w if r[kw.index("kind")] == "rep"]
assert len(points) == 6 and len(reps) == 12, f"the unsharded run: {len(points)} points, {len(reps)} repetitions"
assert w == s, "rows differ:\n" + "\n".join(str(x) for x in sorted(set(w) ^ set(s)))
md = (sharded / "report.md").read_text()
assert "Points: 6 of 6 in these files (6 measured)" in md and "incomplete" not in md, "report.md: not 6 of 6 points"
per_shard = [len(json.load(open(shards / f"part-{i}.json"))["points"]) for i in range(4)]
assert per_shard == [2, 2, 1, 1], f"points per shard {per_shard}; want point k in shard k mod 4"
print(f"sweep: {len(points)} points, {len(reps)} repetitions, {len(w)} CSV rows equal (shards {per_shard})")
PY
note "sharded sweep equals the unsharded one"

# ---- 2. sharded validation == unsharded validation ---------------------------------------
trace="$tmp/flipped.h5"
"$octocd" run "$src/datasets/scenes/rot-stack-10.json" --engine bullet --rotation --frames 120 --state-every 1 \
  --contacts --trace "$trace" --no-xdmf --quiet >/dev/null || fail "octocd run (bullet, rot-stack-10) exited $?"
"$py" -c '
import sys, h5py
with h5py.File(sys.argv[1], "r+") as f:
    n = f["/contacts/normal"]
    assert n.shape[0] > 100, n.shape
    n[...] = -n[...]  # planted: every normal points from A to B' "$trace" || fail "planting flipped normals"
"$octocd" validate --trace-in "$trace" --every 5 --json "$tmp/whole/verdict.json" >/dev/null
rc=$?
[ "$rc" = 3 ] || fail "unsharded validate of the flipped trace exited $rc; want 3 (rows fail)"
note "trace and its unsharded verdict"
"$submit" validate "$trace" --octocd "$octocd" --run-dir "$tmp/validate" --shards 4 --partition debug --wait \
  -- --every 5 >"$tmp/validate.out" 2>&1
rc=$?
cat "$tmp/validate.out"
[ "$rc" = 3 ] || fail "submit.sh validate --wait exited $rc; want 3 (the merged verdict fails as the whole one)"
"$py" - "$tmp/whole/verdict.json" "$tmp/validate/verdict.json" <<'PY' || fail "the merged verdict differs"
import json, sys
whole, merged = (json.load(open(p)) for p in sys.argv[1:])
def whole_run(c):  # a finding about the whole trace (frame -1, e.g. the impulse ratio) is
    # fitted per shard: its text names the shard's sample (docs/validation.md)
    for e in c.get("examples", []):
        if e.get("frame", 0) < 0:
            e.pop("text", None)
    return c
def rows(d):  # every field but the detail line (the first failing shard's) and the seconds
    return [{k: ([whole_run(c) for c in v] if k == "causes" else v) for k, v in r.items()
             if k not in ("detail", "seconds")} for r in d["rows"]]
w, m = rows(whole), rows(merged)
assert len(w) == len(m), f"{len(w)} rows vs {len(m)}"
for a, b in zip(w, m):
    assert a == b, f"row {a['tier']}/{a['name']}:\n whole  {json.dumps(a)[:400]}\n merged {json.dumps(b)[:400]}"
assert len(merged.get("merged_from", [])) == 4, merged.get("merged_from")
failing = [r["name"] for r in m if r["verdict"] == "fail"]
assert "contact-geometry" in failing, failing
print(f"validate: {len(m)} rows equal, failing {failing}")
PY
grep -q "contact-geometry" "$tmp/validate/verdict.txt" || fail "no table in verdict.txt"
[ -s "$tmp/validate/verdict.xml" ] || fail "no JUnit verdict.xml"
note "sharded validation equals the unsharded one"

# ---- 3. a cancelled array task: the join fails naming it ---------------------------------
# The jobs run this wrapper as their octocd: shard 2/4 reports its array id on one FIFO and
# blocks on another, until scancel ends it.
mkfifo "$tmp/reached" "$tmp/release" || fail mkfifo
cat >"$tmp/octocd-held" <<EOF
#!/bin/bash
case " \$* " in
  *" --shard 2/4 "*) echo "\$SLURM_ARRAY_JOB_ID" >"$tmp/reached"; read -r _ <"$tmp/release" ;;
esac
exec "$octocd" "\$@"
EOF
chmod +x "$tmp/octocd-held"
"$submit" validate "$trace" --octocd "$tmp/octocd-held" --run-dir "$tmp/cancel" --shards 4 --wait -- --every 5 \
  >"$tmp/cancel.out" 2>&1 &
submit_pid=$!
array=$(timeout 60 cat "$tmp/reached") || fail "shard 2/4 did not start within 60 s"
[[ "$array" =~ ^[0-9]+$ ]] || fail "shard 2/4 reported array id '$array'"
scancel "${array}_2" || fail "scancel ${array}_2"
note "cancelled array task ${array}_2"
wait "$submit_pid"
rc=$?
cat "$tmp/cancel.out"
[ "$rc" = 1 ] || fail "submit.sh --wait after a cancelled shard exited $rc; want 1"
grep -q "shard 2/4 (array task ${array}_2.*did not finish" "$tmp/cancel/logs/join.log" \
  || fail "join.log does not name shard 2/4 as unfinished"
grep -q "shard 2/4 (array task ${array}_2" "$tmp/cancel.out" || fail "submit.sh's output does not name shard 2/4"
! grep -q "shard [013]/4" "$tmp/cancel/logs/join.log" || fail "join.log names a shard that finished"
[ ! -e "$tmp/cancel/verdict.json" ] || fail "the join merged without shard 2/4"
for i in 0 1 3; do [ "$(cat "$tmp/cancel/status/$i.rc")" = 3 ] || fail "shard $i/4's status is not 3"; done
# validate --merge itself refuses the three shards left.
"$octocd" validate --merge "$tmp/cancel/shards/shard-0.json" "$tmp/cancel/shards/shard-1.json" \
  "$tmp/cancel/shards/shard-3.json" >"$tmp/merge3.out" 2>&1
rc=$?
[ "$rc" = 2 ] || fail "validate --merge of shards 0, 1, 3 exited $rc; want 2"
grep -q "shard 2/4 (frames 61..90) is missing" "$tmp/merge3.out" || fail "validate --merge: $(cat "$tmp/merge3.out")"
note "the cancelled shard is named by the join and by validate --merge"

# ---- 4. the join's checks of a sweep, by hand on copies of the run folder ------------------
join_fails() {  # CASE PATTERN: the join on folder CASE exits 1, naming PATTERN, reporting nothing
  local dir="$tmp/$1"
  bash "$join" sweep "$dir" 4 4242 "$octocd" >"$dir.out" 2>&1
  local rc=$?
  [ "$rc" = 1 ] || fail "join on $1 exited $rc; want 1: $(cat "$dir.out")"
  grep -q -- "$2" "$dir.out" || fail "join on $1 does not say '$2': $(cat "$dir.out")"
  [ ! -e "$dir/report" ] || fail "join on $1 wrote a report"
}
fresh() { rm -rf "$tmp/$1"; cp -r "$tmp/sweep" "$tmp/$1" && rm -rf "$tmp/$1/report" "$tmp/$1/status/join.rc"; }
fresh no-status && rm "$tmp/no-status/status/1.rc"
join_fails no-status "shard 1/4 (array task 4242_1, Slurm state .*did not finish"
fresh bad-status && echo 134 >"$tmp/bad-status/status/0.rc"
join_fails bad-status "shard 0/4 (array task 4242_0): octocd exited with status 134"
fresh unfinished && "$py" -c '
import json, sys
p = sys.argv[1]; d = json.load(open(p)); d["complete"] = False; d["stopped"] = "SIGTERM"; d["points"] = d["points"][:1]
json.dump(d, open(p, "w"))' "$tmp/unfinished/shards/part-3.json"
join_fails unfinished "shard 3/4 (.*part-3.json): unfinished (complete: false, stopped by SIGTERM, 1 point(s) kept)"
fresh foreign && cp "$tmp/sweep/shards/part-0.json" "$tmp/foreign/shards/part-1.json"
join_fails foreign "shard 1/4 (.*part-1.json): settings.shard is 0/4; allowed: 1/4"
fresh lost-point && "$py" -c '
import json, sys
p = sys.argv[1]; d = json.load(open(p)); d["points"] = d["points"][1:]
json.dump(d, open(p, "w"))' "$tmp/lost-point/shards/part-2.json"
join_fails lost-point "the shards hold 5 point(s) of the sweep's 6: point 2 (of shard 2/4) missing"
# bench exits 2 when every point of its shard is skipped (after writing its result): the
# join takes such a shard, and refuses status 2 beside measured points.
fresh skipped-shard && "$py" -c '
import json, sys
p = sys.argv[1]; d = json.load(open(p))
for pt in d["points"]:  # as bench writes a skipped point: no measurements, a reason
    for k in ("windows", "series", "wall_s", "has_stage", "device", "engine_broadphase", "repetition_start_s"):
        pt.pop(k, None)
    pt.update({"status": "skipped", "reason": "planted: engine not available"})
json.dump(d, open(p, "w"))' "$tmp/skipped-shard/shards/part-3.json"
echo 2 >"$tmp/skipped-shard/status/3.rc"
cp -r "$tmp/skipped-shard" "$tmp/status2-measured"
cp "$tmp/sweep/shards/part-3.json" "$tmp/status2-measured/shards/part-3.json"
join_fails status2-measured "shard 3/4 (.*part-3.json): octocd exited with status 2 (bad input), its result holds measured points"
bash "$join" sweep "$tmp/skipped-shard" 4 4242 "$octocd" >"$tmp/skipped-shard.out" 2>&1 \
  || fail "join with an all-skipped shard 3 (status 2) exited $?: $(cat "$tmp/skipped-shard.out")"
[ -s "$tmp/skipped-shard/report/index.html" ] || fail "join with an all-skipped shard wrote no report"
note "the join refuses a missing status, a bad status, an unfinished, a foreign and a short shard; takes an all-skipped one"

elapsed=$((SECONDS - t_start))
echo "PASS: sharded sweep and validation through Slurm equal the unsharded runs; a cancelled shard fails the join ($elapsed s)"
