#!/usr/bin/env bash
# Submit one `ground-sim insar` map made in blocks to Slurm: a job array with one task per block
# (`--block $SLURM_ARRAY_TASK_ID/N`, 0-based) and a mosaic job that starts when every block has
# succeeded (`--dependency=afterok`). N comes from `insar --plan-blocks` with the same flags.
#
#   tools/slurm-insar-blocks.sh OUT_DIR ARGS...
#
# ARGS are `insar`'s own (--dem, --pixel-m, --block-cells, radar flags, ...), without --out,
# --block or --mosaic; paths must be visible from the compute nodes (jobs run in the current
# folder). Block i writes OUT_DIR/blocks/block-iii/ and its log OUT_DIR/slurm/block-i.log; the
# mosaic writes the map products into OUT_DIR and its log OUT_DIR/slurm/mosaic.log.
#
# Environment:
#   GROUND_SIM     the binary, on a shared filesystem (default: ground-sim on PATH, else
#                  target/release/ground-sim of this checkout)
#   CPUS_PER_TASK  cores per block task (default 4)
#   MEM_PER_TASK   memory per block task (default 2G: a 400-cell block of the default radar
#                  peaks near 1 GiB)
#   SBATCH_ARGS    more sbatch options for both jobs, e.g. "--partition=cpu --time=01:00:00"
#   DRY_RUN=1      write the job scripts and print the sbatch commands without submitting
set -euo pipefail

if [[ $# -lt 2 ]]; then
    sed -n '2,22p' "$0" >&2
    exit 2
fi
out=$1
shift
here=$(cd "$(dirname "$0")/.." && pwd)
bin=${GROUND_SIM:-$(command -v ground-sim || echo "$here/target/release/ground-sim")}
[[ -x $bin ]] || {
    echo "slurm-insar-blocks: no ground-sim binary at '$bin' (build with cargo build --release -p ground-sim, or set GROUND_SIM)" >&2
    exit 2
}
bin=$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")
plan=$("$bin" insar --out "$out" "$@" --plan-blocks)
n=$(awk '{print $2}' <<<"$plan")
if ! [[ $n =~ ^[0-9]+$ ]] || ((n < 2)); then
    echo "slurm-insar-blocks: this map fits one piece ($plan); run ground-sim insar directly" >&2
    exit 2
fi
cpus=${CPUS_PER_TASK:-4}
mem=${MEM_PER_TASK:-2G}
mkdir -p "$out/slurm"
out=$(cd "$out" && pwd)
read -r -a extra <<<"${SBATCH_ARGS:-}"
for p in "$out" "$PWD"; do
    if [[ $p =~ [[:space:]] ]]; then
        echo "slurm-insar-blocks: '$p' has whitespace, which #SBATCH --chdir/--output cannot carry" >&2
        exit 2
    fi
done
args=$(printf '%q ' "$@")
q() { printf '%q' "$1"; }

cat >"$out/slurm/block.sbatch" <<JOB
#!/usr/bin/env bash
#SBATCH --job-name=umbra-insar-block
#SBATCH --array=0-$((n - 1))
#SBATCH --ntasks=1
#SBATCH --cpus-per-task=$cpus
#SBATCH --mem=$mem
#SBATCH --chdir=$PWD
#SBATCH --output=$out/slurm/block-%a.log
set -euo pipefail
export RAYON_NUM_THREADS=\${SLURM_CPUS_PER_TASK:-$cpus}
i=\$SLURM_ARRAY_TASK_ID
exec $(q "$bin") insar $args--out $(q "$out") --no-progress --block "\$i/$n"
JOB

cat >"$out/slurm/mosaic.sbatch" <<JOB
#!/usr/bin/env bash
#SBATCH --job-name=umbra-insar-mosaic
#SBATCH --ntasks=1
#SBATCH --cpus-per-task=$cpus
#SBATCH --chdir=$PWD
#SBATCH --output=$out/slurm/mosaic.log
set -euo pipefail
exec $(q "$bin") insar $args--out $(q "$out") --no-progress --mosaic
JOB

if [[ ${DRY_RUN:-0} == 1 ]]; then
    echo "$plan"
    echo "sbatch --parsable ${extra[*]} $out/slurm/block.sbatch"
    echo "sbatch --parsable ${extra[*]} --dependency=afterok:<array job id> $out/slurm/mosaic.sbatch"
    exit 0
fi
array=$(sbatch --parsable "${extra[@]}" "$out/slurm/block.sbatch")
array=${array%%;*}
mosaic=$(sbatch --parsable "${extra[@]}" --dependency="afterok:$array" "$out/slurm/mosaic.sbatch")
mosaic=${mosaic%%;*}
echo "submitted: block array $array ($n tasks), mosaic $mosaic after all of them succeed"
echo "results:   $out/report.json (squeue -j $array,$mosaic; logs in $out/slurm/)"
