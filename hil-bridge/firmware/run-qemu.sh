#!/usr/bin/env bash
# cargo runner for the firmware (see .cargo/config.toml): replays a recorded link session
# through QEMU without a host runner, then prints what the firmware answered.
#   - the session (hello, 3 frames, shutdown) comes from `hil-bridge record`;
#   - QEMU's working directory holds hil-link.rx (that file) and hil-link.tx (the answers).
# The interactive, fault-injecting, bit-comparing run is `cargo run --release -p hil-bridge -- run`.
set -euo pipefail
elf="$(realpath "$1")"
shift
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
dir="$root/target/hil/replay"
machine="${UMBRA_QEMU_MACHINE:-mps2-an386}"
cpu=cortex-m4
[[ "$machine" == *an500* ]] && cpu=cortex-m7
if ! command -v qemu-system-arm >/dev/null; then
  echo "qemu-system-arm not found (apt-get install qemu-system-arm)" >&2
  exit 2
fi
(cd "$root" && cargo run --release -q -p hil-bridge -- record --frames 3 --out "$dir/hil-link.rx")
cd "$dir"
: > hil-link.tx
qemu-system-arm -machine "$machine" -cpu "$cpu" -nographic -monitor none -serial null \
  -semihosting-config enable=on,target=native -icount shift=0,align=off,sleep=off \
  -kernel "$elf" "$@"
echo "--- firmware answers (hil-link.tx) ---"
(cd "$root" && cargo run --release -q -p hil-bridge -- decode "$dir/hil-link.tx") | grep -v "Ack(" || true
