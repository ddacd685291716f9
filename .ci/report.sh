#!/usr/bin/env bash
# The HTML report in a real browser (issue 19): runs the README's report
# command (the naive KR-270 job with --output), opens DIR/report.html in
# headless Chromium and fails when
#   - Chromium logs any console message (the page has no script: any message
#     is an error of the page, e.g. a malformed element),
#   - the rendered DOM lacks a section of the report or an inline figure,
#   - the screenshot is missing or blank (a near-empty PNG).
# Installs Debian's chromium when it is missing. Leaves the page and its
# screenshot in target/report/ (report.html, report.png).
set -euo pipefail
cd "$(dirname "$0")/.."

if ! command -v chromium >/dev/null; then
    sudo=
    if [ "$(id -u)" -ne 0 ]; then sudo=sudo; fi
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends chromium >/dev/null
fi

out=target/report
rm -rf "$out"
# The test step's build of the command (debug, `--features cli`): the same
# report, bit for bit, as a release build's (no floating-point optimisation
# differs between the profiles), without a second, LTO build.
# The test step's build (the README test command's packages and features:
# `cargo build --bin robcal` alone would build the library again).
cargo test --workspace --features cli --no-run --quiet
./target/debug/robcal calibrate -q \
    --setup data/kr270/setup-naive.toml --data data/kr270/measurements.csv \
    --validate data/kr270/measurements.csv --output "$out" >/dev/null

profile=$(mktemp -d)
log=$(mktemp)
trap 'rm -rf "$profile" "$log"' EXIT
# The flags that keep Chromium off the (closed) network and out of its
# sandbox (CI runs as root).
chrome=(chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run
    --disable-background-networking --disable-component-update --disable-sync
    --user-data-dir="$profile" --enable-logging=stderr --v=0 --hide-scrollbars)
page="file://$(pwd)/$out/report.html"

timeout 120 "${chrome[@]}" --dump-dom "$page" >"$out/dom.html" 2>"$log"
timeout 120 "${chrome[@]}" --window-size=1100,2200 --screenshot="$out/report.png" "$page" 2>>"$log" >/dev/null

failed=0
fail() { echo "report: FAILED: $*" >&2; failed=1; }
if grep -F ':CONSOLE' "$log"; then
    fail "console messages while loading the page"
fi
for id in job summary loop parameters correlations identifiability validation warnings figures; do
    grep -qF "<section id=\"$id\">" "$out/dom.html" || fail "no section '$id' in the rendered page"
done
figures=$(grep -o '<svg' "$out/dom.html" | wc -l)
[ "$figures" -ge 4 ] || fail "$figures inline figures rendered, expected at least 4"
grep -qF 'compensator on a2' "$out/dom.html" || fail "the closed loop's step is missing"
size=$(stat -c %s "$out/report.png" 2>/dev/null || echo 0)
[ "$size" -gt 50000 ] || fail "screenshot $size bytes (blank?)"
[ "$failed" -eq 0 ] || exit 1
echo "report: ok: $figures figures, 9 sections, no console message, screenshot $size bytes ($out/report.png)"
