#!/bin/bash
# Brings up a single-node Slurm cluster on this machine (munge, slurmctld and slurmd, with a
# configuration of its own in a temporary directory; Debian packages slurm-wlm and munge, which
# tools/setup.sh installs when missing), renders the Cornell box as a 4-task job array of shards plus a
# dependent merge job (tools/slurm/submit.sh), and checks that the merged image equals a
# single-process render of the same options byte for byte. Stops the daemons it started.
#
#   tools/slurm_test.sh [PATH_TO_GATETRACE]   (default: target/release/gatetrace, else target/debug)
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
bin=${1:-}
if [ -z "$bin" ]; then
    for b in "${CARGO_TARGET_DIR:-$repo/target}"/{release,debug}/gatetrace; do
        if [ -x "$b" ]; then bin=$b; break; fi
    done
fi
[ -x "$bin" ] || { echo "slurm_test: no gatetrace binary (build it first or pass its path)" >&2; exit 1; }
bin=$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")
. "$repo/tools/setup.sh"
gatetrace_setup_slurm

work=$(mktemp -d /tmp/gatetrace-slurm.XXXXXX)
pids=()
cleanup() {
    for p in "${pids[@]}"; do kill "$p" 2> /dev/null || true; done
    wait 2> /dev/null || true
    # The daemons save their state as they stop (they are not this shell's children, so `wait`
    # does not wait for them): give them up to 10 s, then remove the directory; a leftover
    # temporary directory fails nothing.
    for _ in $(seq 100); do
        alive=0
        for p in "${pids[@]}"; do kill -0 "$p" 2> /dev/null && alive=1; done
        [ "$alive" = 0 ] && break
        sleep 0.1
    done
    rm -rf "$work" 2> /dev/null || { sleep 1; rm -rf "$work" 2> /dev/null; } || true
}
trap cleanup EXIT

# munge: a key of our own and a socket in the work directory.
mkdir -p "$work/munge"
dd if=/dev/urandom of="$work/munge/munge.key" bs=1 count=1024 status=none
chmod 700 "$work/munge" && chmod 400 "$work/munge/munge.key"
socket="$work/munge/munge.socket"
munged --force --key-file="$work/munge/munge.key" --socket="$socket" --pid-file="$work/munge/munged.pid" \
    --log-file="$work/munge/munged.log" --seed-file="$work/munge/munged.seed"
pids+=("$(cat "$work/munge/munged.pid")")

host=$(hostname -s)
cpus=$(nproc)
memory=$(awk '/MemTotal/ {print int($2 / 1024 / 2)}' /proc/meminfo)
mkdir -p "$work/state" "$work/spool" "$work/log"
cat > "$work/slurm.conf" <<CONF
ClusterName=gatetrace-test
SlurmctldHost=$host(127.0.0.1)
SlurmUser=$(id -un)
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$socket
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/log/slurmctld.log
SlurmdLogFile=$work/log/slurmd.log
SlurmctldPort=46817
SlurmdPort=46818
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
SwitchType=switch/none
MpiDefault=none
ReturnToService=2
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$memory State=UNKNOWN
PartitionName=test Nodes=$host Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
CONF
export SLURM_CONF=$work/slurm.conf
slurmctld -f "$SLURM_CONF" && sleep 1
pids+=("$(cat "$work/slurmctld.pid")")
slurmd -f "$SLURM_CONF"
for _ in $(seq 50); do [ -f "$work/slurmd.pid" ] && break; sleep 0.2; done
pids+=("$(cat "$work/slurmd.pid")")
for _ in $(seq 100); do
    sinfo -h -o %T 2> /dev/null | grep -q idle && break
    sleep 0.3
done
sinfo -h -o "%P %D %T" | grep -q idle || { echo "slurm_test: the node did not come up" >&2; cat "$work/log/"*; exit 1; }
echo "slurm_test: single-node cluster up ($host, $cpus CPUs)"

cd "$repo"
options=(assets/scenes/cornell_box.gltf --method direct --gate box:3.14..3.19 --res 32x32 --spp 40 --max-bounces 4
         --samples-per-pass 8)
GATETRACE="$bin" tools/slurm/submit.sh 4 "$work/parts" "$work/merged.npy" "${options[@]}"
# Wait for the queue to empty (the merge job runs last).
for _ in $(seq 600); do
    [ -z "$(squeue -h -o %i)" ] && break
    sleep 0.5
done
[ -z "$(squeue -h -o %i)" ] || { echo "slurm_test: jobs still queued after 300 s" >&2; squeue; exit 1; }
[ -f "$work/merged.npy" ] || { echo "slurm_test: the merge job wrote no image" >&2; cat "$work/parts/"*.out; exit 1; }
ls "$work/parts"/part_*.shard | wc -l | grep -qx 4 || { echo "slurm_test: expected 4 shards" >&2; exit 1; }
"$bin" render "${options[@]}" --out "$work/single.npy" > /dev/null
if cmp "$work/merged.npy" "$work/single.npy"; then
    echo "slurm_test: passed: 4 array tasks + merge equal the single-process render byte for byte"
else
    echo "slurm_test: FAILED: the merged image differs from the single-process render" >&2
    exit 1
fi
