#!/usr/bin/env bash
# Slurm (issue 5): a single-host Slurm (munged, slurmctld, slurmd; ../shared/recipes) runs a planned
# job as one 4-task array per stage (integrate, regularize, ..., sort; each after the one before with
# afterok) plus a dependent merge, byte-identical to the single-process mesh; a failing tile fails
# its array, and the later stages and the merge are cancelled, writing nothing. Needs root and the Debian
# packages slurmctld slurmd slurm-client munge; skipped (77) without them.
# Usage: slurm_test.sh SCALEFUSE SHARED_DATA WORK
set -euo pipefail
BIN=$1 SHARED=$2 W=$3
source "$(dirname "$0")/common.sh"
for p in munged mungekey slurmctld slurmd sbatch sinfo squeue scontrol; do
  command -v "$p" >/dev/null || { echo "SKIP: $p not installed"; exit 77; }
done
[ "$(id -u)" = 0 ] || { echo "SKIP: a single-host Slurm needs root"; exit 77; }
rm -rf "$W" && mkdir -p "$W"
D=$W/slurm-host

stop_slurm() {
  for f in "$D"/run/slurmd.pid "$D"/run/slurmctld.pid "$D"/munge/munged.pid; do
    [ -s "$f" ] && kill "$(cat "$f")" 2>/dev/null || true
  done
}
trap stop_slurm EXIT

# --- a single-host cluster, all state under $D -----------------------------------------------
mkdir -p "$D"/{munge,state/ctld,state/d,log,run}
chmod 700 "$D/munge"
mungekey --create --keyfile="$D/munge/munge.key" >/dev/null 2>&1
chmod 600 "$D/munge/munge.key"
munged --force --socket="$D/munge/munge.socket" --key-file="$D/munge/munge.key" --pid-file="$D/munge/munged.pid" \
  --log-file="$D/log/munged.log" --seed-file="$D/munge/munged.seed"
NODE=$(hostname -s)
CPUS=$(nproc)
MEM=$(( $(free -m | awk '/^Mem:/{print $2}') - 512 ))
# Ports away from a system Slurm's; jobs stay visible 10 minutes after they end (their final states
# are checked below).
cat > "$D/slurm.conf" <<CONF
ClusterName=scalefuse-test
SlurmctldHost=${NODE}(127.0.0.1)
SlurmctldPort=16817
SlurmdPort=16818
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$D/munge/munge.socket
StateSaveLocation=$D/state/ctld
SlurmdSpoolDir=$D/state/d
SlurmctldPidFile=$D/run/slurmctld.pid
SlurmdPidFile=$D/run/slurmd.pid
SlurmctldLogFile=$D/log/slurmctld.log
SlurmdLogFile=$D/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SwitchType=switch/none
MpiDefault=none
MailProg=/bin/true
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MinJobAge=600
SlurmdParameters=config_overrides
NodeName=${NODE} NodeAddr=127.0.0.1 CPUs=${CPUS} RealMemory=${MEM} State=UNKNOWN
PartitionName=ci Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$D/slurm.conf
# In a network namespace with nothing but loopback, slurmctld fails in getaddrinfo unless lo has a
# second address (../shared/recipes/cluster-on-one-machine.md).
if command -v ip >/dev/null && [ "$(ip -o link show | grep -vc ': lo:')" = 0 ]; then
  ip addr add 127.0.0.2/8 dev lo 2>/dev/null || true
fi
slurmctld -f "$SLURM_CONF"
slurmd -f "$SLURM_CONF"
for i in $(seq 120); do
  [ "$(timeout 5 sinfo -h -N -o %T 2>/dev/null)" = idle ] && break
  sleep 0.25
done
[ "$(timeout 5 sinfo -h -N -o %T 2>/dev/null)" = idle ] || { tail -20 "$D"/log/*.log; fail "slurmd did not come up"; }
echo "ok: single-host Slurm up ($CPUS cores, $MEM MiB)"

scene_and_reference "$BIN" "$SHARED" "$W"

# waits (at most 10 minutes) until none of the given Slurm jobs is pending or running
wait_for_jobs() {
  for i in $(seq 2400); do
    [ -z "$(timeout 5 squeue -h -j "$(IFS=,; echo "$*")" -o %i 2>/dev/null)" ] && return 0
    sleep 0.25
  done
  timeout 5 squeue || true
  fail "Slurm jobs $* did not finish within 10 minutes"
}
state_of() { timeout 5 scontrol -o show job "$1" | grep -o 'JobState=[A-Z_]*' | sort -u | tr '\n' ' '; }

# --- 4 tiles as an array per stage, then the merge ---------------------------------------------------------
"$BIN" plan "$SCENE" --tiles 4 --job "$W/ok.job" -o "$W/ok.ply" -q "${FUSE_ARGS[@]}" > /dev/null
"$BIN" slurm "$W/ok.job" --cpus 1 --mem 1G --time 20:00 --partition ci --submit
read -r TILES MERGE < "$W/ok.job/slurm/submitted"
wait_for_jobs "$TILES" "$MERGE"
[ -s "$W/ok.ply" ] || { tail -5 "$W"/ok.job/slurm/*.log; fail "the merge wrote no mesh (array: $(state_of "$TILES"), merge: $(state_of "$MERGE"))"; }
same_bytes "$REF" "$W/ok.ply" "Slurm array of 4 tiles + merge"

# --- a failing tile: the array fails, the merge is cancelled -------------------------------------
"$BIN" plan "$SCENE" --tiles 4 --job "$W/bad.job" -o "$W/bad.ply" -q "${FUSE_ARGS[@]}" > /dev/null
SCALEFUSE_TEST_FAIL_TILE=1 "$BIN" slurm "$W/bad.job" --cpus 1 --mem 1G --time 20:00 --partition ci --submit
read -r TILES MERGE < "$W/bad.job/slurm/submitted"
wait_for_jobs "$TILES" "$MERGE"
tiles_state=$(state_of "$TILES")
merge_state=$(state_of "$MERGE")
[[ $tiles_state == *FAILED* ]] || fail "the array's states are '$tiles_state', expected a FAILED task"
[[ $merge_state == *CANCELLED* ]] || fail "the merge's state is '$merge_state', expected CANCELLED"
[ ! -e "$W/bad.ply" ] || fail "a mesh was written although a tile failed"
grep -q "failure injected" "$W/bad.job/slurm/integrate-1.log" || fail "tile 1's log does not say why it failed"
# The later stages' arrays never ran: cancelled with the merge.
last_stage=$(sed -n 's/^stages:.* \([0-9]*\)$/\1/p' "$W/bad.job/slurm/submitted")
[ -n "$last_stage" ] || fail "submitted lists no stage arrays"
[[ $(state_of "$last_stage") == *CANCELLED* ]] || fail "the last stage's array is '$(state_of "$last_stage")', expected CANCELLED"
echo "ok: a failing tile fails the array ($tiles_state) and cancels the merge ($merge_state)"
