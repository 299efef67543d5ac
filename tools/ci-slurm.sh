#!/usr/bin/env bash
# Run the project's Slurm scripts under a real single-node Slurm (Debian's slurm-wlm 22.05:
# munged, slurmctld, slurmd on this machine) and check that what they produce is byte for byte
# what one process produces:
#
#   - tools/slurm-campaign.sh: an `eval` campaign (21 frames) and a `descent` campaign (4 runs)
#     as job arrays of 3 shards plus an afterok merge job, against the unsharded runs;
#   - tools/slurm-insar-blocks.sh: a 1.6 km map in 2 x 2 blocks as a job array plus the mosaic
#     job, against the same map made in one process.
#
#   tools/ci-slurm.sh [WORK_DIR]
#
# Needs root (or password-less sudo) to install the packages and start the daemons. Slurm's
# configuration and state live in WORK_DIR/slurm (SLURM_CONF points there), so no file under
# /etc/slurm is written; the daemons are stopped on exit. The munge key is the package's.
#
# Environment:
#   GROUND_SIM   the binary to test (default target/release/ground-sim, else target/debug/)
set -euo pipefail

here=$(cd "$(dirname "$0")/.." && pwd)
work=${1:-$(mktemp -d /tmp/umbra-slurm.XXXXXX)}
mkdir -p "$work"
work=$(cd "$work" && pwd)
bin=${GROUND_SIM:-}
if [[ -z $bin ]]; then
    for b in "$here/target/release/ground-sim" "$here/target/debug/ground-sim"; do
        if [[ -x $b ]]; then bin=$b && break; fi
    done
fi
[[ -n $bin && -x $bin ]] || {
    echo "ci-slurm: no ground-sim binary (cargo build -p ground-sim, or set GROUND_SIM)" >&2
    exit 2
}
bin=$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")
export GROUND_SIM=$bin
SUDO=""
[[ $(id -u) == 0 ]] || SUDO="sudo -n"

# --- packages -----------------------------------------------------------------------------
if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null ||
    ! command -v sbatch >/dev/null || ! command -v munged >/dev/null; then
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
        slurmctld slurmd slurm-client munge >/dev/null
fi
slurmctld -V

# --- a one-node cluster: this machine, all its cores ------------------------------------------
conf_dir=$work/slurm
mkdir -p "$conf_dir/ctld" "$conf_dir/d" "$conf_dir/log"
host=$(hostname -s)
cpus=$(nproc)
mem_mb=$(($(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 512))
export SLURM_CONF=$conf_dir/slurm.conf
cat >"$SLURM_CONF" <<CONF
ClusterName=umbra-ci
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
AuthType=auth/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
MpiDefault=none
ReturnToService=2
SchedulerType=sched/backfill
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
StateSaveLocation=$conf_dir/ctld
SlurmdSpoolDir=$conf_dir/d
SlurmctldLogFile=$conf_dir/log/slurmctld.log
SlurmdLogFile=$conf_dir/log/slurmd.log
SlurmctldPidFile=$conf_dir/slurmctld.pid
SlurmdPidFile=$conf_dir/slurmd.pid
SlurmctldPort=6917
SlurmdPort=6918
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=ci Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF

submitted_ids=""
stop() {
    local rc=$?
    # Jobs still queued or running would keep the cores busy after the daemons stop.
    if [[ -n $submitted_ids ]]; then timeout 10 scancel ${submitted_ids//,/ } 2>/dev/null || true; fi
    for p in "$conf_dir/slurmd.pid" "$conf_dir/slurmctld.pid"; do
        if [[ -f $p ]]; then $SUDO kill "$(cat "$p")" 2>/dev/null || true; fi
    done
    if ((rc != 0)); then
        echo "--- slurmctld.log (tail)"
        tail -20 "$conf_dir/log/slurmctld.log" 2>/dev/null || true
        echo "--- slurmd.log (tail)"
        tail -20 "$conf_dir/log/slurmd.log" 2>/dev/null || true
    fi
    exit "$rc"
}
trap stop EXIT

# munged: a socket file is no proof that it runs (a machine image taken while it ran keeps
# /run/munge's socket and pid file, and every connection is refused), so ask it for a
# credential; when it does not answer, clear what the dead one left and start it.
# (The client retries a refused connection for a while: each probe is capped.)
munge_ok() { timeout 5 munge -n </dev/null 2>/dev/null | timeout 5 unmunge >/dev/null 2>&1; }
if ! munge_ok; then
    $SUDO rm -f /run/munge/munge.socket.2 /run/munge/munge.socket.2.lock /run/munge/munged.pid
    $SUDO mkdir -p /run/munge
    $SUDO chown munge:munge /run/munge 2>/dev/null || true
    if [[ -z $SUDO ]]; then
        runuser -u munge -- /usr/sbin/munged || /usr/sbin/munged --force
    else
        $SUDO -u munge /usr/sbin/munged || $SUDO /usr/sbin/munged --force
    fi
    t0=$SECONDS
    while ((SECONDS - t0 < 20)); do munge_ok && break; sleep 0.5; done
    munge_ok || {
        echo "ci-slurm: munged does not answer" >&2
        $SUDO tail -20 /var/log/munge/munged.log >&2 || true
        exit 1
    }
fi
echo "munged answers"
$SUDO env SLURM_CONF="$SLURM_CONF" /usr/sbin/slurmctld
$SUDO env SLURM_CONF="$SLURM_CONF" /usr/sbin/slurmd
# Bounded in time, not in tries: an sinfo that cannot authenticate waits ~50 s per call.
up=0
t0=$SECONDS
while ((SECONDS - t0 < 120)); do
    if timeout 10 sinfo -h -o %t 2>/dev/null | grep -qx idle; then up=1 && break; fi
    sleep 1
done
((up)) || {
    echo "ci-slurm: the single-node Slurm did not come up in 120 s" >&2
    timeout 10 sinfo >&2 || true
    exit 1
}
sinfo

# Wait until Slurm holds none of the jobs named in $1 (comma list); fail after 10 min, on a
# dependency that can no longer be met (a task failed before its afterok job), or when a job
# ended other than COMPLETED (slurmctld keeps ended jobs for MinJobAge, 300 s; no accounting
# database is needed to ask it).
wait_jobs() {
    local ids=$1 t0=$SECONDS q
    while true; do
        # squeue fails once a job id has left the controller, and when it is slow: then ask
        # scontrol whether any of the jobs is still live, and go on waiting if so.
        if ! q=$(timeout 30 squeue -h -j "$ids" -o '%i %T %r' 2>/dev/null); then
            local live
            live=$(for id in ${ids//,/ }; do timeout 10 scontrol -o show job "$id" 2>/dev/null || true; done |
                grep -cE 'JobState=(PENDING|CONFIGURING|RUNNING|COMPLETING|SUSPENDED)' || true)
            [[ $live == 0 ]] && break
            if ((SECONDS - t0 > 600)); then
                echo "ci-slurm: squeue does not answer for jobs $ids" >&2
                return 1
            fi
            sleep 2
            continue
        fi
        [[ -n $q ]] || break
        if grep -q DependencyNeverSatisfied <<<"$q" || ((SECONDS - t0 > 600)); then
            echo "ci-slurm: jobs $ids will not finish:" >&2
            echo "$q" >&2
            return 1
        fi
        sleep 2
    done
    local states
    states=$(for id in ${ids//,/ }; do scontrol -o show job "$id"; done |
        grep -o 'JobState=[A-Z_]*' | sort | uniq -c)
    echo "  job states: $(tr -s ' \n' ' ' <<<"$states")"
    if grep -v -q 'JobState=COMPLETED' <<<"$states"; then
        echo "ci-slurm: jobs $ids did not all complete" >&2
        return 1
    fi
}
job_ids() { sed -n 's/^submitted: shard array \([0-9]*\).*, merge \([0-9]*\) after.*/\1,\2/p; s/^submitted: block array \([0-9]*\).*, mosaic \([0-9]*\) after.*/\1,\2/p'; }

# Print what a submission script said, then wait for the two jobs it names (array, merge).
wait_submitted() {
    local ids
    echo "$1"
    ids=$(job_ids <<<"$1")
    if [[ -z $ids ]]; then
        echo "ci-slurm: no job ids in: $1" >&2
        return 1
    fi
    submitted_ids=${submitted_ids:+$submitted_ids,}$ids
    wait_jobs "$ids"
}

same() {
    if cmp -s "$1" "$2"; then
        echo "  same bytes: $(basename "$1")"
    else
        echo "ci-slurm: $1 and $2 differ" >&2
        exit 1
    fi
}

# --- a campaign: eval and descent, 3 shards each --------------------------------------------
cd "$work"
"$bin" terrain --preset shoemaker --seed 3 --size-m 8000 --pixel-m 10 --out dem.tif >/dev/null
"$bin" tile --dem dem.tif --out ref >/dev/null
# With a prior, as in flight (lost in space against this whole 8 km tile the work budget leaves
# no room past matching).
eval_args=(--tile ref --dem dem.tif --trials 21 --seed 5 --prior-sigma-m 50 --prior-heading-sigma-deg 2 --no-host-time)
descent_args=(--tile ref --dem dem.tif --runs 4 --seed 2 --hop-min-m 2000 --hop-max-m 2500)
"$bin" eval "${eval_args[@]}" --json single/eval.json >/dev/null
"$bin" descent "${descent_args[@]}" --json single/descent.json >/dev/null 2>&1

for cmd in eval descent; do
    if [[ $cmd == eval ]]; then args=("${eval_args[@]}"); else args=("${descent_args[@]}"); fi
    wait_submitted "$(CPUS_PER_TASK=1 "$here/tools/slurm-campaign.sh" 3 "slurm-$cmd" "$cmd" "${args[@]}")"
    echo "$cmd: 3 Slurm shards + merge against one process"
    same single/$cmd.json "slurm-$cmd/$cmd.json"
done
same single/eval.csv slurm-eval/eval.csv
for png in descent-trajectory.png descent-error.png descent-hazard.png; do
    same "single/$png" "slurm-descent/$png"
done

# --- a map in blocks: 2 x 2 blocks as array tasks, then the mosaic --------------------------
"$bin" terrain --preset lola --seed 5 --size-m 1600 --pixel-m 10 --out map-dem.tif >/dev/null
map_args=(--dem map-dem.tif --block-cells 40 --block-overlap-cells 8)
"$bin" insar --out map-one --no-progress "${map_args[@]}" >/dev/null
wait_submitted "$(CPUS_PER_TASK=1 MEM_PER_TASK=1G "$here/tools/slurm-insar-blocks.sh" map-slurm "${map_args[@]}")"
echo "insar: 4 Slurm block tasks + mosaic against one process"
n=0
for f in map-one/*.tif map-one/*.png map-one/tile.bin map-one/tile.json; do
    [[ -f $f ]] || continue
    same "$f" "map-slurm/${f#map-one/}"
    n=$((n + 1))
done
((n >= 5)) || {
    echo "ci-slurm: only $n map products compared" >&2
    exit 1
}
echo "ci-slurm: every Slurm-made output equals the one-process output"
