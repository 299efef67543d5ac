#!/usr/bin/env bash
# Make one `ground-sim insar` map in blocks as P background processes on this machine, then
# mosaic it: the split a Slurm job array makes (tools/slurm-insar-blocks.sh), without a
# scheduler. Each process makes blocks i, i+P, i+2P, ...
#
#   tools/local-blocks.sh P OUT_DIR ARGS...
#
# ARGS are `insar`'s own (--dem, --pixel-m, --block-cells, radar flags, ...), without --out,
# --block or --mosaic. Logs go to OUT_DIR/logs/worker-i.log. Every process gets
# RAYON_NUM_THREADS (default: cores / P, at least 1). Memory: P blocks at once.
#
# GROUND_SIM names the binary (default: ground-sim on PATH, else target/release/ground-sim).
set -euo pipefail

if [[ $# -lt 3 ]]; then
    sed -n '2,13p' "$0" >&2
    exit 2
fi
p=$1 out=$2
shift 2
if ! [[ $p =~ ^[0-9]+$ ]] || ((p < 1)); then
    echo "local-blocks: P must be an integer ≥ 1, got '$p'" >&2
    exit 2
fi
here=$(cd "$(dirname "$0")/.." && pwd)
bin=${GROUND_SIM:-$(command -v ground-sim || echo "$here/target/release/ground-sim")}
[[ -x $bin ]] || {
    echo "local-blocks: no ground-sim binary at '$bin' (build with cargo build --release -p ground-sim, or set GROUND_SIM)" >&2
    exit 2
}
plan=$("$bin" insar --out "$out" "$@" --plan-blocks)
n=$(awk '{print $2}' <<<"$plan")
if ! [[ $n =~ ^[0-9]+$ ]] || ((n < 2)); then
    echo "local-blocks: this map fits one piece ($plan); run ground-sim insar directly" >&2
    exit 2
fi
threads=${RAYON_NUM_THREADS:-$(($(nproc) / p > 0 ? $(nproc) / p : 1))}
mkdir -p "$out/logs"
pids=()
for ((w = 0; w < p; w++)); do
    (
        for ((i = w; i < n; i += p)); do
            RAYON_NUM_THREADS=$threads "$bin" insar "$@" --out "$out" --no-progress --block "$i/$n"
        done
    ) >"$out/logs/worker-$w.log" 2>&1 &
    pids+=($!)
done
failed=0
for ((w = 0; w < p; w++)); do
    if ! wait "${pids[$w]}"; then
        echo "local-blocks: worker $w failed; its log:" >&2
        cat "$out/logs/worker-$w.log" >&2
        failed=1
    fi
done
((failed == 0)) || exit 1
"$bin" insar "$@" --out "$out" --no-progress --mosaic
