#!/bin/bash
# Bakes through a real SLURM on this one machine (Debian's slurm-wlm and munge): starts
# munged, slurmctld and slurmd with a private configuration, then checks that
#   1. a 4-task job array (scripts/slurm/submit.sh) gives caches whose sections are
#      identical (xxh3 of every section) to a single-process bake, and a manifest;
#   2. a task cancelled mid-way (scancel), with the array resubmitted, resumes: the finished
#      steps are kept, not baked again, and the series verifies.
# Run as root (the daemons need it). $SLOSH names the binary. Exits non-zero on any failure.
#
#   SLOSH=target/debug/slosh scripts/slurm/test.sh
set -euo pipefail
slosh=$(readlink -f "${SLOSH:-slosh}")
export SLOSH=$slosh
here=$(dirname "$(readlink -f "$0")")
work=$(mktemp -d /tmp/slosh-slurm.XXXXXX)
export SLURM_CONF=$work/slurm.conf
host=$(hostname)

stop() {
    scancel --quiet --user="$(id -un)" 2>/dev/null || true
    for pid in "$work/slurmd.pid" "$work/slurmctld.pid"; do
        [ -f "$pid" ] && kill "$(cat "$pid")" 2>/dev/null || true
    done
}
trap stop EXIT

echo "== SLURM on $host, in $work"
mkdir -p "$work/state" "$work/spool"
cat >"$SLURM_CONF" <<CONF
ClusterName=slosh-test
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
ReturnToService=2
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MinJobAge=600
NodeName=$host CPUs=$(nproc) RealMemory=2000 State=UNKNOWN
PartitionName=test Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
if ! pgrep -x munged >/dev/null; then
    mkdir -p /run/munge /var/log/munge /var/lib/munge
    chown munge:munge /run/munge /var/log/munge /var/lib/munge 2>/dev/null || true
    [ -f /etc/munge/munge.key ] || mungekey --create 2>/dev/null || /usr/sbin/create-munge-key -f
    munged --force
fi
slurmctld -f "$SLURM_CONF"
slurmd -f "$SLURM_CONF"
for _ in $(seq 60); do
    sinfo -h -o %t 2>/dev/null | grep -q idle && break
    sleep 1
done
sinfo

# Waits until every job in "$@" has left the queue; fails unless each ended COMPLETED.
wait_jobs() {
    while [ -n "$(squeue -h -j "$(
        IFS=,
        echo "$*"
    )" 2>/dev/null)" ]; do
        sleep 1
    done
    for job in "$@"; do
        states=$(scontrol show job "$job" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | sort -u)
        if [ "$states" != "JobState=COMPLETED" ]; then
            echo "job $job ended: $states" >&2
            cat "$work"/*.logs/*"$job"* >&2 2>/dev/null || true
            return 1
        fi
    done
}

# Every section's xxh3 of every step of cache directory $1, one line per step.
section_sums() {
    for f in "$1"/step-*.slc; do
        "$slosh" inspect "$f" --json | python3 -c '
import json, sys
h = json.load(sys.stdin)["header"]
print(h["source"]["step"], " ".join(s["name"] + ":" + s["xxh3"] for s in h["sections"]))'
    done
}

echo "== 1. a 4-task array against one process"
"$slosh" gen sphere --points 3000 --steps 16 --out "$work/in" >/dev/null
"$slosh" bake "$work/in/sphere.case" --out "$work/one" --jobs 1 --quiet
read -r array manifest < <("$here/submit.sh" 4 "$work/in/sphere.case" "$work/array" -- --quiet)
echo "array job $array, manifest job $manifest"
wait_jobs "$array" "$manifest"
one=$(section_sums "$work/one")
arr=$(section_sums "$work/array")
if [ "$one" != "$arr" ]; then
    diff <(echo "$one") <(echo "$arr") >&2 || true
    echo "FAIL: the array's sections differ from the single-process bake" >&2
    exit 1
fi
echo "16 steps, every section identical to the single-process bake"
"$slosh" inspect "$work/array" --verify >/dev/null
echo "manifest rebuilt after the array; the series verifies"

echo "== 2. a task cancelled mid-way, the array resubmitted"
"$slosh" gen sphere --points 40000 --steps 12 --out "$work/big" >/dev/null
read -r array manifest < <("$here/submit.sh" 2 "$work/big/sphere.case" "$work/resume" -- --quiet)
# Task 0 owns steps 0, 2, 4, …: cancel it once it has written two of them.
for _ in $(seq 600); do
    [ "$(ls "$work/resume"/step-0000[02468].slc 2>/dev/null | wc -l)" -ge 2 ] && break
    sleep 0.2
done
scancel "${array}_0"
echo "cancelled task 0 of $array with $(ls "$work/resume"/step-*.slc | wc -l) step files written"
while [ -n "$(squeue -h -j "$array")" ]; do sleep 1; done
scancel "$manifest" 2>/dev/null || true
before=$(ls "$work/resume"/step-*.slc | wc -l)
read -r array manifest < <("$here/submit.sh" 2 "$work/big/sphere.case" "$work/resume" -- --quiet)
wait_jobs "$array" "$manifest"
log=$(cat "$work/resume.logs/bake-${array}_0.out")
echo "task 0 again: $log"
kept=$(echo "$log" | grep -o 'kept [0-9]*' | grep -o '[0-9]*')
if [ -z "$kept" ] || [ "$kept" -lt 2 ]; then
    echo "FAIL: the resubmitted task 0 kept ${kept:-no} steps" >&2
    exit 1
fi
"$slosh" inspect "$work/resume" --verify >/dev/null
echo "$before step files before the resubmission; task 0 kept $kept of its 6; 12 steps verify"
echo "== SLURM test passed"
