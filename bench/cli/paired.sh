#!/usr/bin/env bash
# Whole-process timing of a command, alone or paired with a second one
# (issue 16): the CLI's goals are whole runs of `robcal calibrate`, start-up,
# parsing and report included, so they are timed from outside the process.
#
#   bench/cli/paired.sh [-n RUNS] [--vs 'COMMAND_B'] -- COMMAND_A [ARG ...]
#
# One warm-up run of each command (not counted), then RUNS runs of A (default
# 5); with --vs, A and B in turn — A B A B … — and the ratio A / B taken pair
# by pair, so that a machine whose speed drifts during the call (a shared
# host) moves both sides of a ratio alike. COMMAND_B is one string split at
# white space (no quoting, no shell); put a variable before it with `env`:
#   --vs "env ROBCAL_MAX_HELD_DESIGN_ROWS=0 target/release/robcal calibrate …"
# What the commands print is thrown away.
#
# Printed per command: wall seconds (the clock read by `date +%s%N` just
# before and after the child; GNU time's own start-up, about a millisecond,
# is in it),
# CPU seconds (user + system) and peak resident memory in MiB (the largest
# resident set of the process, as GNU time's %M reports it), each as the
# median [min, max]; with --vs, the paired A / B wall ratio the same way.
# Quote the median: min and max show how noisy the machine was.
#
# Needs bash, GNU time (/usr/bin/time, Debian package `time`), awk and sort.
set -euo pipefail

runs=5
vs=""
while [ $# -gt 0 ]; do
    case "$1" in
        -n) runs=$2; shift 2 ;;
        --vs) vs=$2; shift 2 ;;
        --) shift; break ;;
        *) echo "usage: $0 [-n RUNS] [--vs 'COMMAND_B'] -- COMMAND_A [ARG ...]" >&2; exit 2 ;;
    esac
done
[ $# -gt 0 ] || { echo "usage: $0 [-n RUNS] [--vs 'COMMAND_B'] -- COMMAND_A [ARG ...]" >&2; exit 2; }
[ -x /usr/bin/time ] || { echo "$0: needs GNU time at /usr/bin/time (apt-get install time)" >&2; exit 2; }
a=("$@")
b=()
[ -n "$vs" ] && read -r -a b <<< "$vs"

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# one run: appends "wall cpu peak_mib" to $1
run() {
    local out=$1; shift
    local t0 t1 rc=0
    t0=$(date +%s%N)
    /usr/bin/time -f "%U %S %M" -o "$tmp/time" "$@" > /dev/null 2>&1 || rc=$?
    t1=$(date +%s%N)
    [ "$rc" -eq 0 ] || echo "$0: exit status $rc: $*" >&2
    tail -n 1 "$tmp/time" | awk -v w="$(( t1 - t0 ))" \
        '{ printf "%.4f %.4f %.1f\n", w / 1e9, $1 + $2, $3 / 1024 }' >> "$out"
}

run /dev/null "${a[@]}"
[ ${#b[@]} -gt 0 ] && run /dev/null "${b[@]}"
for _ in $(seq "$runs"); do
    run "$tmp/a" "${a[@]}"
    [ ${#b[@]} -gt 0 ] && run "$tmp/b" "${b[@]}"
done

# median [min, max] of column $2 of file $1
stat() {
    cut -d' ' -f"$2" "$1" | sort -g | awk '{ v[NR] = $1 }
        END { m = (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2;
              printf "%.3f [%.3f, %.3f]", m, v[1], v[NR] }'
}
report() {
    printf '%s: wall %s s, cpu %s s, peak %s MiB\n' "$1" "$(stat "$2" 1)" "$(stat "$2" 2)" "$(stat "$2" 3)"
}
echo "A: ${a[*]}"
[ ${#b[@]} -gt 0 ] && echo "B: ${b[*]}"
echo "$runs runs each, $(date -u +%H:%M) UTC, load $(cut -d' ' -f1-3 /proc/loadavg)"
report A "$tmp/a"
if [ ${#b[@]} -gt 0 ]; then
    report B "$tmp/b"
    paste -d' ' "$tmp/a" "$tmp/b" | awk '{ print $1 / $4 }' > "$tmp/ratio"
    printf 'A / B wall, pair by pair: %s\n' "$(stat "$tmp/ratio" 1)"
fi
