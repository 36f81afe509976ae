#!/usr/bin/env bash
# CTest entry: a one-node Slurm cluster on this machine (munged, slurmctld, slurmd with a
# generated configuration and state in a temporary folder), a coordinator on loopback with
# access tokens, deploy/slurm/tessera-workers.sbatch submitted with sbatch (each worker
# enrolling with the enrolment token for a credential of its own), a render job through them;
# the workers are scancel'ed mid-job and submitted again; the image must equal
# `tessera render` bit for bit, and the allocation must end by itself once idle. Every
# daemon it started is stopped by its PID. Skips, saying why, where Slurm or munge is
# missing or the daemons cannot start.
set -euo pipefail
build=$(cd "${1:?build directory}" && pwd)
root=$(cd "$(dirname "$0")/../.." && pwd)
for b in munged slurmctld slurmd sbatch squeue scancel sinfo; do
  command -v "$b" >/dev/null || { echo "SKIP: $b is not installed (deploy/install-deps.sh installs slurm-wlm, munge)"; exit 77; }
done
[ "$(id -u)" -eq 0 ] || { echo "SKIP: the Slurm daemons need root here"; exit 77; }
T=$(mktemp -d /tmp/tessera-slurm.XXXXXX)
chmod 755 "$T"
pids=()
cleanup() {
  set +e
  # Jobs first (their steps outlive slurmd), then the daemons, then any straggler.
  if [ -n "${SLURM_CONF:-}" ]; then
    scancel --full --user=root 2>/dev/null
    for _ in $(seq 50); do [ -z "$(squeue -h 2>/dev/null)" ] && break; sleep 0.1; done
  fi
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null; done
  pkill -f -- "$T" 2>/dev/null
  rm -rf "$T"
}
trap cleanup EXIT
skip() { echo "SKIP: $1"; shift; for f in "$@"; do [ -f "$f" ] && tail -5 "$f"; done; exit 77; }
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }

# munge, with a key and socket of our own.
dd if=/dev/urandom of="$T/munge.key" bs=1024 count=1 status=none
chmod 400 "$T/munge.key"
munged --foreground --force --key-file="$T/munge.key" --socket="$T/munge.sock" --pid-file="$T/munged.pid" \
  --log-file="$T/munged.log" --seed-file="$T/munge.seed" 2>>"$T/munged.log" &
pids+=($!)
for _ in $(seq 50); do [ -S "$T/munge.sock" ] && break; sleep 0.1; done
[ -S "$T/munge.sock" ] || skip "munged did not start" "$T/munged.log"

host=$(hostname -s)
cpus=$(nproc)
mkdir -p "$T/state" "$T/spool"
cat >"$T/slurm.conf" <<CONF
ClusterName=tessera-test
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
SlurmctldPort=$(free_port)
SlurmdPort=$(free_port)
AuthType=auth/munge
AuthInfo=socket=$T/munge.sock
CredType=cred/munge
StateSaveLocation=$T/state
SlurmdSpoolDir=$T/spool
SlurmctldPidFile=$T/slurmctld.pid
SlurmdPidFile=$T/slurmd.pid
SlurmctldLogFile=$T/slurmctld.log
SlurmdLogFile=$T/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MpiDefault=none
SlurmdTimeout=30
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=tessera Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF="$T/slurm.conf"
slurmctld -D -i -f "$SLURM_CONF" >"$T/slurmctld.out" 2>&1 &
pids+=($!)
slurmd -D -f "$SLURM_CONF" >"$T/slurmd.out" 2>&1 &
pids+=($!)
up=""
for _ in $(seq 100); do
  if sinfo -h -o '%T' 2>/dev/null | grep -q idle; then up=1; break; fi
  sleep 0.2
done
[ -n "$up" ] || skip "the Slurm daemons did not bring the node up" "$T/slurmctld.log" "$T/slurmd.log" "$T/slurmd.out"

# The coordinator, outside the cluster, on loopback, with tokens as docs/deploy.md makes
# them: the workers get only the enrolment token.
(umask 077
 for who in enrol client viewer; do openssl rand -hex 24 >"$T/$who.token"; done
 printf 'enrol farm-enrol %s\nclient me %s\nviewer ops %s\n' "$(cat "$T/enrol.token")" "$(cat "$T/client.token")" \
   "$(cat "$T/viewer.token")" >"$T/tokens")
auth="Authorization: Bearer $(cat "$T/viewer.token")"
flags=(-r 160 120 -s 384 --pass-spp 8 -m 6 --seed 4)  # long enough (~15 s on 2 cores) that scancel lands mid-job
"$build/bin/tessera" render "$root/scenes/cornell-spheres.dae" "${flags[@]}" -q -f "$T/local.exr"
"$build/bin/tessera-coordinator" --listen 127.0.0.1:0 --http 127.0.0.1:0 --data "$T/data" \
  --lease-seconds 2 --tokens-file "$T/tokens" >"$T/coord.out" 2>"$T/coord.err" &
pids+=($!)
for _ in $(seq 100); do grep -q "http listening" "$T/coord.out" && break; sleep 0.1; done
addr=$(sed -n 's/^grpc listening on \([^ ]*\).*/\1/p' "$T/coord.out")
http=$(sed -n 's/^http listening on \([^ ]*\).*/\1/p' "$T/coord.out")
[ -n "$addr" ] || { echo "FAIL: the coordinator did not start"; cat "$T/coord.err"; exit 1; }
samples() { curl -s -H "$auth" "http://$http/api/status" | python3 -c 'import json,sys; j=json.load(sys.stdin)["jobs"]; print(j[0]["samples_done"] if j else 0)'; }
state() { curl -s -H "$auth" "http://$http/api/status" | python3 -c 'import json,sys; j=json.load(sys.stdin)["jobs"]; print(j[0]["state"] if j else "")'; }

submit_workers() {
  (cd "$T" && TESSERA_COORDINATOR="$addr" TESSERA_BIN="$build/bin" TESSERA_IDLE_SECONDS=3 TESSERA_CACHE="$T/cache" \
    TESSERA_ENROL_TOKEN_FILE="$T/enrol.token" sbatch --parsable "$root/deploy/slurm/tessera-workers.sbatch")
}
job=$(submit_workers)
echo "slurm job $job: workers"
export TESSERA_TOKEN_FILE="$T/client.token"  # the client's, for submit and fetch
id=$("$build/bin/tessera" submit "$root/scenes/cornell-spheres.dae" "${flags[@]}" --coordinator "$addr" -q)
echo "render job $id"
# Mid-job: cancel the workers' allocation, then submit them again.
for _ in $(seq 300); do [ "$(samples)" != "0" ] && break; sleep 0.1; done
[ "$(samples)" != "0" ] || { echo "FAIL: the Slurm workers rendered nothing"; tail -20 "$T"/tessera-workers-*.out "$T/slurmd.log"; exit 1; }
scancel "$job"
for _ in $(seq 100); do [ -z "$(squeue -h -j "$job" 2>/dev/null)" ] && break; sleep 0.1; done
[ "$(state)" != "DONE" ] || { echo "FAIL: the job ended before the workers were cancelled: make it longer"; exit 1; }
echo "cancelled $job at $(samples) samples"
job=$(submit_workers)
echo "slurm job $job: workers again"
for _ in $(seq 600); do [ "$(state)" = "DONE" ] && break; sleep 0.1; done
[ "$(state)" = "DONE" ] || { echo "FAIL: the render did not finish"; tail -20 "$T"/tessera-workers-*.out; exit 1; }
"$build/bin/tessera" fetch "$id" --coordinator "$addr" -f "$T/farm.exr" >/dev/null
"$build/bin/tessera_compare" "$T/farm.exr" "$T/local.exr" | tee "$T/compare.json"
grep -q '"identical":true' "$T/compare.json" || { echo "FAIL: the image differs from tessera render"; exit 1; }
# Idle for 3 s: the allocation ends by itself.
for _ in $(seq 200); do [ -z "$(squeue -h -j "$job" 2>/dev/null)" ] && break; sleep 0.1; done
[ -z "$(squeue -h -j "$job" 2>/dev/null)" ] || { echo "FAIL: the workers did not leave when idle"; exit 1; }
grep -q "exit-when-idle" "$T"/tessera-workers-"$job".out || { echo "FAIL: no idle exit in the log"; cat "$T"/tessera-workers-"$job".out; exit 1; }
# Each allocation's worker enrolled for a credential of its own.
enrolled=$(grep -c 'event=worker.enrolled worker=[^ ]* who=farm-enrol' "$T/coord.err" || true)
[ "$enrolled" -ge 2 ] || { echo "FAIL: the workers did not enrol ($enrolled enrolments)"; tail -20 "$T/coord.err"; exit 1; }
echo "PASS: Slurm workers enrolled, scancel mid-job and again, bit-identical; the allocation ended when idle"
