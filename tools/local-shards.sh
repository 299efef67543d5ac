#!/usr/bin/env bash
# Run one `ground-sim eval` or `descent` campaign as N shards in background processes on this
# machine, then merge them: the same split a Slurm job array makes (tools/slurm-campaign.sh),
# without a scheduler.
#
#   tools/local-shards.sh N OUT_DIR eval|descent ARGS...
#
# ARGS are the command's own (--tile, --dem, --trials/--runs, --seed, ...), without --json or
# --shard. Shard i (0-based) writes OUT_DIR/shards/shard-i.json (eval: and its CSV) and its log
# OUT_DIR/shards/shard-i.log; the merge writes OUT_DIR/eval.json + eval.csv, or
# OUT_DIR/descent.json + the run-0 pictures. Every shard process gets RAYON_NUM_THREADS
# (default: cores / N, at least 1) so that N processes do not oversubscribe the cores.
#
# GROUND_SIM names the binary (default: ground-sim on PATH, else target/release/ground-sim).
set -euo pipefail

if [[ $# -lt 3 ]]; then
    sed -n '2,16p' "$0" >&2
    exit 2
fi
n=$1 out=$2 cmd=$3
shift 3
if ! [[ $n =~ ^[0-9]+$ ]] || ((n < 1)); then
    echo "local-shards: N must be an integer ≥ 1, got '$n'" >&2
    exit 2
fi
case $cmd in
eval | descent) ;;
*)
    echo "local-shards: the command must be eval or descent, got '$cmd'" >&2
    exit 2
    ;;
esac

here=$(cd "$(dirname "$0")/.." && pwd)
bin=${GROUND_SIM:-$(command -v ground-sim || echo "$here/target/release/ground-sim")}
[[ -x $bin ]] || {
    echo "local-shards: no ground-sim binary at '$bin' (build with cargo build --release -p ground-sim, or set GROUND_SIM)" >&2
    exit 2
}
threads=${RAYON_NUM_THREADS:-$(( $(nproc) / n > 0 ? $(nproc) / n : 1 ))}

mkdir -p "$out/shards"
pids=()
for ((i = 0; i < n; i++)); do
    RAYON_NUM_THREADS=$threads "$bin" "$cmd" "$@" --shard "$i/$n" \
        --json "$out/shards/shard-$i.json" >"$out/shards/shard-$i.log" 2>&1 &
    pids+=($!)
done
failed=0
for ((i = 0; i < n; i++)); do
    if ! wait "${pids[$i]}"; then
        echo "local-shards: shard $i/$n failed; its log:" >&2
        cat "$out/shards/shard-$i.log" >&2
        failed=1
    fi
done
((failed == 0)) || exit 1

shards=()
for ((i = 0; i < n; i++)); do shards+=("$out/shards/shard-$i.json"); done
"$bin" merge --json "$out/$cmd.json" "${shards[@]}"
