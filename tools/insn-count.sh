#!/usr/bin/env bash
# Exact instruction counts, flash, RAM and stack of the firmware example
# under QEMU (see BENCHMARKS.md).
#
#   tools/insn-count.sh [PROFILE [TARGET...]]
#   ROBCAL_EXAMPLE=firmware_plan tools/insn-count.sh   # another firmware example
#
# PROFILE: cargo profile, `firmware` (default: release + opt-level "s") or
# `release` (opt-level 3). TARGET: thumbv7em-none-eabihf (Cortex-M4F on
# mps2-an386) and/or thumbv7m-none-eabi (Cortex-M3 on lm3s6965evb); default
# both.
#
# How: tools/insnmark.c (a QEMU TCG plugin) counts executed guest
# instructions and prints the running count each time the firmware executes
# `bench_mark()`. The firmware brackets each measured call with two marks
# and logs `bench phase K: NAME` after it; phase K's count is
# mark(2K+1) − mark(2K) minus the bracket overhead (phase 0, empty).
# Flash = .vector_table + .text + .rodata + .data (its load image);
# static RAM = .data + .bss + .uninit; the stack high-water mark is measured
# by the firmware (painted stack, scanned at the end).
set -euo pipefail

cd "$(dirname "$0")/.."
profile=${1:-firmware}
shift || true
example=${ROBCAL_EXAMPLE:-firmware}
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(thumbv7em-none-eabihf thumbv7m-none-eabi)
fi

llvm_bin="$(rustc --print sysroot)/lib/rustlib/$(rustc -vV | sed -n 's/^host: //p')/bin"
if [ ! -x "$llvm_bin/llvm-size" ]; then
    rustup component add llvm-tools
fi

target_dir=${CARGO_TARGET_DIR:-target}
out=$target_dir/insn-count
mkdir -p "$out"
plugin=$out/libinsnmark.so
if [ ! -f "$plugin" ] || [ tools/insnmark.c -nt "$plugin" ]; then
    gcc -O2 -shared -fPIC -fvisibility=hidden -o "$plugin" tools/insnmark.c
fi

for target in "${targets[@]}"; do
    case $target in
        thumbv7em-none-eabihf) machine=mps2-an386 cpu=cortex-m4 ;;
        thumbv7m-none-eabi) machine=lm3s6965evb cpu=cortex-m3 ;;
        *) echo "unknown target $target" >&2; exit 2 ;;
    esac
    cargo build --quiet --profile "$profile" --target "$target" --example "$example"
    elf=$target_dir/$target/$profile/examples/$example
    mark=$("$llvm_bin/llvm-nm" "$elf" | awk '$3 == "bench_mark" { print $1 }')
    if [ -z "$mark" ]; then
        echo "bench_mark not found in $elf" >&2
        exit 1
    fi
    marks=$out/$target-$profile-$example.marks
    log=$out/$target-$profile-$example.log
    rm -f "$marks"
    QEMU_EXTRA="-plugin $plugin,mark=0x$mark -d plugin -D $marks" \
        tools/qemu-run.sh "$machine" "$cpu" "$elf" >"$log" 2>&1 || {
        cat "$log" >&2
        echo "$example failed on $target" >&2
        exit 1
    }

    echo "## $example: $target ($cpu on QEMU $machine), profile $profile"
    echo
    echo "| phase | instructions |"
    echo "| --- | ---: |"
    # Join the marks (file 1) with the phase names from the defmt log (file 2).
    awk '
        FNR == NR && /insnmark: mark/ { m[$3] = $5; next }
        FNR == NR && /insnmark: total/ { total = $4; next }
        FNR != NR && match($0, /bench phase [0-9]+: .*/) {
            s = substr($0, RSTART + 12, RLENGTH - 12)
            k = s + 0; name = substr(s, index(s, ": ") + 2)
            d = m[2 * k + 1] - m[2 * k]
            if (k == 0) { overhead = d; printf "| %s | %d |\n", name, d }
            else printf "| %s | %d |\n", name, d - overhead
        }
        END { printf "| whole run (total) | %d |\n", total }
    ' "$marks" "$log"
    echo
    "$llvm_bin/llvm-size" -A "$elf" | awk -v logfile="$log" '
        { sz[$1] = $2 }
        END {
            flash = sz[".vector_table"] + sz[".text"] + sz[".rodata"] + sz[".data"]
            ram = sz[".data"] + sz[".bss"] + sz[".uninit"]
            while ((getline line < logfile) > 0)
                if (match(line, /stack high-water mark: [0-9]+/))
                    stack = substr(line, RSTART + 23, RLENGTH - 23) + 0
            printf "| memory | bytes |\n| --- | ---: |\n"
            printf "| flash: .vector_table %d + .text %d + .rodata %d + .data %d | %d |\n", \
                sz[".vector_table"], sz[".text"], sz[".rodata"], sz[".data"], flash
            printf "| static RAM: .data %d + .bss %d + .uninit %d | %d |\n", \
                sz[".data"], sz[".bss"], sz[".uninit"], ram
            printf "| stack high-water mark (measured) | %d |\n", stack
            printf "| RAM total (static + stack) | %d |\n", ram + stack
        }'
    echo
done
