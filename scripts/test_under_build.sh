#!/usr/bin/env bash
# `make test` N times in a row while another cargo build keeps the machine busy (issue 15:
# the suite's wall-clock asserts must hold on a loaded 2-core machine).
#
#   scripts/test_under_build.sh            # 3 runs
#   scripts/test_under_build.sh 5          # 5 runs
#   CONESIGHT_LOAD_FIRST="deploy/arm64/cross-build.sh" scripts/test_under_build.sh
#
# The load is `cargo build --release -p conesight-cli` from scratch in its own target directory
# (build/test-under-build/target), restarted whenever it finishes, so a build runs for the whole
# time; CONESIGHT_LOAD_FIRST runs once before that loop (any other build, e.g. the arm64 cross
# build). Stops at the first red run. Logs and summary.txt in build/test-under-build/.
set -uo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
runs="${1:-3}"
out="build/test-under-build"
mkdir -p "$out"
summary="$out/summary.txt"

load_loop() {
    if [[ -n "${CONESIGHT_LOAD_FIRST:-}" ]]; then
        echo "load: $CONESIGHT_LOAD_FIRST ($(date -u +%T))"
        bash -c "$CONESIGHT_LOAD_FIRST"
        echo "load: first load finished rc=$? ($(date -u +%T))"
    fi
    local round=1
    while true; do
        rm -rf "$out/target"
        echo "load: cargo build --release -p conesight-cli, round $round ($(date -u +%T))"
        cargo build --release -p conesight-cli --target-dir "$out/target" --quiet
        echo "load: round $round finished rc=$? ($(date -u +%T))"
        round=$((round + 1))
    done
}

# The loop in its own process group, so one kill stops cargo, rustc and the loop.
set -m
load_loop >"$out/load.log" 2>&1 &
load_pid=$!
set +m
stop_load() { kill -- -"$load_pid" 2>/dev/null; wait "$load_pid" 2>/dev/null; }
trap stop_load EXIT

{
    echo "make test x $runs under a concurrent cargo build, revision $(git rev-parse --short HEAD)$(git diff --quiet || echo '+changes'), $(nproc) cores, started $(date -u '+%F %T') UTC"
} | tee "$summary"
status=0
for i in $(seq 1 "$runs"); do
    start=$(date +%s)
    make test >"$out/run-$i.log" 2>&1
    rc=$?
    seconds=$(($(date +%s) - start))
    load_now="$(tail -n 1 "$out/load.log" 2>/dev/null)"
    result=$([[ $rc -eq 0 ]] && echo passed || echo "FAILED (rc $rc, see $out/run-$i.log)")
    echo "run $i: $result in ${seconds} s; load average $(cut -d' ' -f1-3 /proc/loadavg); last load line: $load_now" | tee -a "$summary"
    if [[ $rc -ne 0 ]]; then
        status=1
        break
    fi
done
echo "load builds meanwhile:" >>"$summary"
grep '^load:' "$out/load.log" >>"$summary"
exit "$status"
