#!/usr/bin/env bash
# Cargo runner for the bare-metal firmware example (see .cargo/config.toml):
#
#   tools/qemu-run.sh MACHINE CPU ELF [ARG...]
#
# Boots ELF on QEMU's MACHINE with semihosting (ARGs become the firmware's
# semihosting command line, after the ELF's name), pipes the defmt frames the
# firmware writes to semihosting stdout through `defmt-print -e ELF`, and
# exits with QEMU's status, which is the firmware's semihosting exit code
# (0 = pass). A decoder failure also fails the run.
#
# Extra QEMU arguments can be passed in QEMU_EXTRA (e.g. the instruction
# counting plugin, see tools/insn-count.sh).
set -uo pipefail

if [ $# -lt 3 ]; then
    echo "usage: $0 MACHINE CPU ELF [ARG...]" >&2
    exit 2
fi
machine=$1 cpu=$2 elf=$3
shift 3
semihosting=enable=on,target=native,arg=$(basename "$elf")
for arg in "$@"; do
    semihosting+=",arg=$arg"
done

for tool in qemu-system-arm defmt-print; do
    if ! command -v "$tool" >/dev/null; then
        echo "$0: $tool not found (apt-get install qemu-system-arm; cargo install defmt-print --locked)" >&2
        exit 127
    fi
done

# -nographic: no window; -monitor none: stdin is not read; the firmware
# exits through semihosting SYS_EXIT(_EXTENDED). A hung firmware is killed
# after ROBCAL_QEMU_TIMEOUT seconds (default 60).
# shellcheck disable=SC2086
timeout "${ROBCAL_QEMU_TIMEOUT:-60}" \
    qemu-system-arm -machine "$machine" -cpu "$cpu" -nographic -monitor none \
    -semihosting-config "$semihosting" ${QEMU_EXTRA:-} -kernel "$elf" \
    </dev/null | defmt-print -e "$elf"
status=("${PIPESTATUS[@]}")
qemu=${status[0]} decoder=${status[1]}
if [ "$qemu" -eq 124 ]; then
    echo "$0: QEMU timed out" >&2
fi
if [ "$qemu" -eq 0 ] && [ "$decoder" -ne 0 ]; then
    echo "$0: defmt-print failed ($decoder)" >&2
    exit "$decoder"
fi
exit "$qemu"
