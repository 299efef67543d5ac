#!/usr/bin/env bash
# Submit one `ground-sim eval` or `descent` campaign to Slurm: a job array of N shard tasks
# (`--shard $SLURM_ARRAY_TASK_ID/N`, 0-based) and a merge job that starts when every task has
# succeeded (`--dependency=afterok`).
#
#   tools/slurm-campaign.sh N OUT_DIR eval|descent ARGS...
#
# ARGS are the command's own (--tile, --dem, --trials/--runs, --seed, ...), without --json or
# --shard; paths in them must be visible from the compute nodes (jobs run in the current folder).
# Task i writes OUT_DIR/shards/shard-i.json (eval: and its CSV) and OUT_DIR/shards/shard-i.log;
# the merge writes OUT_DIR/eval.json + eval.csv, or OUT_DIR/descent.json + the run-0 pictures,
# and OUT_DIR/merge.log. The job scripts are kept in OUT_DIR/slurm/.
#
# Environment:
#   GROUND_SIM     the binary, on a shared filesystem (default: ground-sim on PATH, else
#                  target/release/ground-sim of this checkout)
#   CPUS_PER_TASK  cores per shard task (default 4; the shard's thread pool uses them all)
#   SBATCH_ARGS    more sbatch options for both jobs, e.g. "--partition=cpu --time=01:00:00"
#   DRY_RUN=1      write the job scripts and print the sbatch commands without submitting
set -euo pipefail

if [[ $# -lt 3 ]]; then
    sed -n '2,22p' "$0" >&2
    exit 2
fi
n=$1 out=$2 cmd=$3
shift 3
if ! [[ $n =~ ^[0-9]+$ ]] || ((n < 1)); then
    echo "slurm-campaign: N must be an integer ≥ 1, got '$n'" >&2
    exit 2
fi
case $cmd in
eval | descent) ;;
*)
    echo "slurm-campaign: the command must be eval or descent, got '$cmd'" >&2
    exit 2
    ;;
esac

here=$(cd "$(dirname "$0")/.." && pwd)
bin=${GROUND_SIM:-$(command -v ground-sim || echo "$here/target/release/ground-sim")}
[[ -x $bin ]] || {
    echo "slurm-campaign: no ground-sim binary at '$bin' (build with cargo build --release -p ground-sim, or set GROUND_SIM)" >&2
    exit 2
}
bin=$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")
cpus=${CPUS_PER_TASK:-4}
mkdir -p "$out/shards" "$out/slurm"
out=$(cd "$out" && pwd)
read -r -a extra <<<"${SBATCH_ARGS:-}"
# #SBATCH lines take a path as it stands, without shell quoting.
for p in "$out" "$PWD"; do
    if [[ $p =~ [[:space:]] ]]; then
        echo "slurm-campaign: '$p' has whitespace, which #SBATCH --chdir/--output cannot carry" >&2
        exit 2
    fi
done

# The command's arguments, quoted once for the job scripts.
args=$(printf '%q ' "$@")
q() { printf '%q' "$1"; }

cat >"$out/slurm/shard.sbatch" <<JOB
#!/usr/bin/env bash
#SBATCH --job-name=umbra-$cmd-shard
#SBATCH --array=0-$((n - 1))
#SBATCH --ntasks=1
#SBATCH --cpus-per-task=$cpus
#SBATCH --chdir=$PWD
#SBATCH --output=$out/shards/shard-%a.log
set -euo pipefail
export RAYON_NUM_THREADS=\${SLURM_CPUS_PER_TASK:-$cpus}
i=\$SLURM_ARRAY_TASK_ID
exec $(q "$bin") $cmd $args--shard "\$i/$n" --json $(q "$out")/shards/shard-\$i.json
JOB

shards=()
for ((i = 0; i < n; i++)); do shards+=("$(q "$out/shards/shard-$i.json")"); done
cat >"$out/slurm/merge.sbatch" <<JOB
#!/usr/bin/env bash
#SBATCH --job-name=umbra-$cmd-merge
#SBATCH --ntasks=1
#SBATCH --cpus-per-task=1
#SBATCH --chdir=$PWD
#SBATCH --output=$out/merge.log
set -euo pipefail
exec $(q "$bin") merge --json $(q "$out")/$cmd.json ${shards[*]}
JOB

if [[ ${DRY_RUN:-0} == 1 ]]; then
    echo "sbatch --parsable ${extra[*]} $out/slurm/shard.sbatch"
    echo "sbatch --parsable ${extra[*]} --dependency=afterok:<array job id> $out/slurm/merge.sbatch"
    exit 0
fi
array=$(sbatch --parsable "${extra[@]}" "$out/slurm/shard.sbatch")
array=${array%%;*} # --parsable prints "jobid[;cluster]"
merge=$(sbatch --parsable "${extra[@]}" --dependency="afterok:$array" "$out/slurm/merge.sbatch")
merge=${merge%%;*}
echo "submitted: shard array $array (${n} tasks), merge $merge after all of them succeed"
echo "results:   $out/$cmd.json (squeue -j $array,$merge; logs in $out/shards/ and $out/merge.log)"
