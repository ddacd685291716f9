#!/usr/bin/env bash
# Bare-metal CI for robcal: builds the firmware example for the Cortex-M4F
# (thumbv7em-none-eabihf, QEMU mps2-an386) and the Cortex-M3
# (thumbv7m-none-eabi, QEMU lm3s6965evb), runs it in QEMU, and fails when
#   - the firmware fails (its semihosting exit status is non-zero),
#   - a failure self-test (wrong reference, panic, HardFault) does NOT fail,
#   - it exceeds the budget: 64 KiB flash, 16 KiB RAM including stack,
#   - the whole KR-270 iterative WLS takes more than 10 M instructions on
#     the Cortex-M4F (issue 17; counted by the QEMU plugin tools/insnmark.c
#     during the same run, as tools/insn-count.sh does),
#   - the firmware's flash table (examples/firmware/kr270_table.rs) is stale
#     against data/kr270 (host build: `--example firmware_table -- --check`).
# Installs what it needs on a fresh Debian machine with rustup: the two
# targets, llvm-tools (llvm-size), qemu-system-arm, defmt-print.
set -euo pipefail
cd "$(dirname "$0")/.."
export PATH="${CARGO_HOME:-$HOME/.cargo}/bin:$PATH"

targets=(thumbv7em-none-eabihf thumbv7m-none-eabi)
rustup target add "${targets[@]}"
rustup component add llvm-tools
if ! command -v qemu-system-arm >/dev/null; then
    sudo=
    if [ "$(id -u)" -ne 0 ]; then sudo=sudo; fi
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends qemu-system-arm
fi
if ! command -v defmt-print >/dev/null; then
    # A debug build: it decodes a few kilobytes of log, and builds in half the time.
    cargo install defmt-print --locked --debug
fi
llvm_bin="$(rustc --print sysroot)/lib/rustlib/$(rustc -vV | sed -n 's/^host: //p')/bin"

flash_budget=$((64 * 1024))
ram_budget=$((16 * 1024))
# The whole KR-270 iterative WLS on the Cortex-M4F (firmware profile).
irls_budget=10000000
irls_phase='kr270 whole iterative WLS'
out=${CARGO_TARGET_DIR:-target}/insn-count
mkdir -p "$out"
plugin=$out/libinsnmark.so
if [ ! -f "$plugin" ] || [ tools/insnmark.c -nt "$plugin" ]; then
    gcc -O2 -shared -fPIC -fvisibility=hidden -o "$plugin" tools/insnmark.c
fi
passed=0
failed=0
pass() { echo "firmware: ok: $*"; passed=$((passed + 1)); }
fail() { echo "firmware: FAILED: $*" >&2; failed=$((failed + 1)); }

# An ELF's flash (.vector_table + .text + .rodata + .data) and static RAM
# (.data + .bss + .uninit) in bytes, and the stack high-water mark the run
# logged in $log (empty when it logged none).
memory() {
    local sizes stack
    sizes=$("$llvm_bin/llvm-size" -A "$1" | awk '
        { s[$1] = $2 }
        END { print s[".vector_table"] + s[".text"] + s[".rodata"] + s[".data"],
                    s[".data"] + s[".bss"] + s[".uninit"] }')
    stack=$(sed -n 's/.*stack high-water mark: \([0-9]*\) bytes.*/\1/p' "$log")
    echo "$sizes $stack"
}

log=$(mktemp)
marks=$(mktemp)
trap 'rm -f "$log" "$marks"' EXIT
# Both targets in one build each: a firmware build is link-time optimised in
# one codegen unit, one core a target, so the two go side by side.
target_flags=()
for target in "${targets[@]}"; do target_flags+=(--target "$target"); done
cargo build --quiet --profile firmware "${target_flags[@]}" --example firmware --example firmware_plan
cargo build --quiet --profile firmware-diagnose "${target_flags[@]}" --example firmware_diagnose

for target in "${targets[@]}"; do
    # The aliases `cargo firmware` / `cargo firmware-m3` (.cargo/config.toml).
    run=(cargo run --quiet --profile firmware --target "$target" --example firmware --)
    cargo build --quiet --profile firmware --target "$target" --example firmware
    elf=${CARGO_TARGET_DIR:-target}/$target/firmware/examples/firmware
    mark=$("$llvm_bin/llvm-nm" "$elf" | awk '$3 == "bench_mark" { print $1 }')

    # The checks, with the instruction counter (tools/qemu-run.sh passes
    # QEMU_EXTRA to QEMU).
    rm -f "$marks"
    if QEMU_EXTRA="-plugin $plugin,mark=0x$mark -d plugin -D $marks" \
        "${run[@]}" 2>&1 | tee "$log"; then
        pass "$target: firmware checks"
    else
        fail "$target: firmware checks"
    fi

    # Phase K's count: mark(2K+1) - mark(2K) - the bracket (phase 0), as
    # tools/insn-count.sh.
    irls=$(awk -v name="$irls_phase" '
        FNR == NR && /insnmark: mark/ { m[$3] = $5; next }
        FNR != NR && match($0, /bench phase [0-9]+: .*/) {
            s = substr($0, RSTART + 12, RLENGTH - 12); k = s + 0
            if (k == 0) overhead = m[1] - m[0]
            if (index(s, name)) print m[2 * k + 1] - m[2 * k] - overhead
        }' "$marks" "$log")
    echo "firmware: $target: whole KR-270 iterative WLS ${irls:-?} instructions"
    if [ "$target" = thumbv7em-none-eabihf ]; then
        if [ -n "$irls" ] && [ "$irls" -le "$irls_budget" ]; then
            pass "$target: KR-270 iterative WLS within $irls_budget instructions"
        else
            fail "$target: KR-270 iterative WLS over $irls_budget instructions (${irls:-not measured})"
        fi
    fi

    read -r flash ram stack < <(memory "$elf")
    echo "firmware: $target: flash $flash B, RAM $ram B + stack ${stack:-?} B"
    if [ "$flash" -le "$flash_budget" ] && [ -n "$stack" ] &&
        [ $((ram + stack)) -le "$ram_budget" ]; then
        pass "$target: within 64 KiB flash, 16 KiB RAM"
    else
        fail "$target: over budget (64 KiB flash, 16 KiB RAM incl. stack)"
    fi

    # Each failure path must end QEMU with a non-zero status.
    for selftest in mismatch panic hardfault; do
        if "${run[@]}" "$selftest" >"$log" 2>&1; then
            cat "$log"
            fail "$target: self-test '$selftest' exited 0"
        else
            pass "$target: self-test '$selftest' fails as it must (exit $?)"
        fi
    done
done

# The table and the host reference it carries must be those of the data.
# The test step's build of the example (the README test command's packages
# and features: `cargo run --example` alone would build the library again).
cargo test --workspace --features cli --no-run --quiet
if target/debug/examples/firmware_table --check; then
    pass "flash table up to date with data/kr270"
else
    fail "flash table stale: cargo run --example firmware_table"
fi

# The closed loop on the device (issue 17, examples/firmware_diagnose): both
# targets; its exit status (the decisions are the host's, the KR-270 RMS
# within 0.1 um of the host's), its diagnosis lines, and the budget: 64 KiB
# flash, 16 KiB RAM including the stack (BENCHMARKS.md).
firmware_diagnose() {
    local target=$1 machine=$2 cpu=$3 elf flash ram stack
    cargo build --quiet --profile firmware-diagnose --target "$target" --example firmware_diagnose
    elf=${CARGO_TARGET_DIR:-target}/$target/firmware-diagnose/examples/firmware_diagnose
    if tools/qemu-run.sh "$machine" "$cpu" "$elf" 2>&1 | tee "$log"; then
        pass "$target: firmware_diagnose checks"
    else
        fail "$target: firmware_diagnose checks"
    fi
    if grep -q 'diagnosis: added compensator on a2, rms 263\.7 -> 123\.8 um' "$log" &&
        grep -q 'diagnosis: added backlash on a5, rms' "$log"; then
        pass "$target: the device names the compensator on a2 and the injected backlash on a5"
    else
        fail "$target: diagnosis lines missing"
    fi
    read -r flash ram stack < <(memory "$elf")
    echo "firmware_diagnose: $target: flash $flash B, RAM $ram B + stack ${stack:-?} B"
    if [ "$flash" -le "$flash_budget" ]; then
        pass "$target: firmware_diagnose within 64 KiB flash"
    else
        fail "$target: firmware_diagnose over 64 KiB flash"
    fi
    if [ -n "$stack" ] && [ $((ram + stack)) -le "$ram_budget" ]; then
        pass "$target: firmware_diagnose within 16 KiB RAM incl. stack"
    else
        fail "$target: firmware_diagnose over 16 KiB RAM incl. stack (or no stack mark)"
    fi
}
firmware_diagnose thumbv7em-none-eabihf mps2-an386 cortex-m4
firmware_diagnose thumbv7m-none-eabi lm3s6965evb cortex-m3

# The next best pose on the device (issue 54, examples/firmware_plan): both
# targets; its exit status (the device's eight choices are the host's
# greedy plan), a wrong sequence must fail, and the budget: 64 KiB flash,
# 16 KiB RAM including the stack.
firmware_plan() {
    local target=$1 machine=$2 cpu=$3 elf flash ram stack
    elf=${CARGO_TARGET_DIR:-target}/$target/firmware/examples/firmware_plan
    if tools/qemu-run.sh "$machine" "$cpu" "$elf" 2>&1 | tee "$log"; then
        pass "$target: firmware_plan chooses the host's configurations"
    else
        fail "$target: firmware_plan checks"
    fi
    read -r flash ram stack < <(memory "$elf")
    echo "firmware_plan: $target: flash $flash B, RAM $ram B + stack ${stack:-?} B"
    if [ "$flash" -le "$flash_budget" ] && [ -n "$stack" ] &&
        [ $((ram + stack)) -le "$ram_budget" ]; then
        pass "$target: firmware_plan within 64 KiB flash, 16 KiB RAM"
    else
        fail "$target: firmware_plan over budget (64 KiB flash, 16 KiB RAM incl. stack)"
    fi
    if tools/qemu-run.sh "$machine" "$cpu" "$elf" mismatch >"$log" 2>&1; then
        cat "$log"
        fail "$target: firmware_plan self-test 'mismatch' exited 0"
    else
        pass "$target: firmware_plan self-test 'mismatch' fails as it must"
    fi
}
firmware_plan thumbv7em-none-eabihf mps2-an386 cortex-m4
firmware_plan thumbv7m-none-eabi lm3s6965evb cortex-m3

echo "firmware: $passed passed, $failed failed"
[ "$failed" -eq 0 ]
