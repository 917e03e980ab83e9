#!/usr/bin/env bash
# Brings a compose stack up, waits until every service's healthcheck says healthy, checks that
# messages flow (each service's conesight_frames_processed_total grows between two /metrics
# reads) and that no container restarted, prints the numbers, and takes the stack down again. Needs Docker, the images
# (deploy/build-images.sh) and curl on the host; not part of `make test`.
#
#   deploy/smoke.sh            # one host: docker-compose.yml
#   deploy/smoke.sh --split    # both sides of deploy/compose.split.yml on this machine
#                              # (JETSON_ADDR=127.0.0.1, two compose projects)
#   deploy/smoke.sh --truth    # renderer's exact boxes from the camera, no detector
#   deploy/smoke.sh --monitoring  # one host plus Prometheus (profile monitoring): all 4 targets up
#   deploy/smoke.sh --keep     # leave the stack running
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

split=0
keep=0
truth=0
monitoring=0
timeout_secs="${SMOKE_TIMEOUT_SECS:-180}"
for arg in "$@"; do
    case "$arg" in
        --split) split=1 ;;
        --keep) keep=1 ;;
        --truth) truth=1 ;;
        --monitoring) monitoring=1 ;;
        -h | --help) sed -n '2,12p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "smoke.sh: unknown argument $arg" >&2; exit 2 ;;
    esac
done

if docker compose version >/dev/null 2>&1; then compose=(docker compose); else compose=(docker-compose); fi
CONESIGHT_MEMLOCK="${CONESIGHT_MEMLOCK:-$(deploy/memlock.sh)}"
export CONESIGHT_MEMLOCK
echo "smoke.sh: CONESIGHT_MEMLOCK=$CONESIGHT_MEMLOCK"

# Each stack: "project|compose args|service:http port ..."
# With --truth the camera publishes the renderer's exact boxes and the detector is scaled to 0.
up_extra=""
detector_service=" detector:9092"
if [[ $truth -eq 1 ]]; then
    export CONESIGHT_CAMERA_FLAGS="--publish-boxes"
    up_extra="--scale detector=0"
    detector_service=""
fi
if [[ $split -eq 0 ]]; then
    profile=""
    [[ $monitoring -eq 1 ]] && profile=" --profile monitoring"
    stacks=("conesight|-f docker-compose.yml${profile}|camera:9091${detector_service} keypoints:9093 localiser:9094")
else
    export JETSON_ADDR=127.0.0.1
    stacks=(
        "conesight-jetson|-f deploy/compose.split.yml --profile jetson|camera:9091${detector_service} keypoints:9093"
        "conesight-carpc|-f deploy/compose.split.yml --profile carpc|localiser:9094"
    )
fi

down() {
    for s in "${stacks[@]}"; do
        IFS='|' read -r project args _ <<<"$s"
        # shellcheck disable=SC2086 # args is a list of words
        "${compose[@]}" -p "$project" $args down -v --remove-orphans >/dev/null 2>&1 || true
    done
}
if [[ $keep -eq 0 ]]; then trap down EXIT; fi

for s in "${stacks[@]}"; do
    IFS='|' read -r project args services <<<"$s"
    extra=""
    [[ "$services" == *camera* ]] && extra="$up_extra"
    echo "smoke.sh: up $project ($args $extra)"
    # shellcheck disable=SC2086 # word lists
    "${compose[@]}" -p "$project" $args up -d $extra
done

container_of() { # project service
    docker ps -q --filter "label=com.docker.compose.project=$1" \
        --filter "label=com.docker.compose.service=$2" | head -n1
}

start=$SECONDS
echo "smoke.sh: waiting up to ${timeout_secs}s for every service to be healthy"
while :; do
    all=1
    line=""
    for s in "${stacks[@]}"; do
        IFS='|' read -r project _ services <<<"$s"
        for sp in $services; do
            svc="${sp%%:*}"
            id="$(container_of "$project" "$svc")"
            status="$( [[ -n "$id" ]] && docker inspect -f '{{.State.Health.Status}}' "$id" || echo missing)"
            line+="$svc=$status "
            [[ "$status" == healthy ]] || all=0
        done
    done
    echo "  t=$((SECONDS - start))s $line"
    [[ $all -eq 1 ]] && break
    if ((SECONDS - start > timeout_secs)); then
        echo "smoke.sh: FAIL: not all healthy after ${timeout_secs}s" >&2
        for s in "${stacks[@]}"; do
            IFS='|' read -r project args _ <<<"$s"
            # shellcheck disable=SC2086
            "${compose[@]}" -p "$project" $args logs --tail 20 >&2 || true
        done
        exit 1
    fi
    sleep 5
done
echo "smoke.sh: all healthy after $((SECONDS - start))s"

processed() { # port
    curl -fsS "http://127.0.0.1:$1/metrics" |
        sed -n 's/^conesight_frames_processed_total\({[^}]*}\)\{0,1\} \([0-9.e+]*\)$/\2/p' | head -n1
}

declare -A first
interval=10
for s in "${stacks[@]}"; do
    IFS='|' read -r _ _ services <<<"$s"
    for sp in $services; do first[$sp]="$(processed "${sp##*:}")"; done
done
sleep "$interval"
failed=0
echo "smoke.sh: conesight_frames_processed_total over ${interval}s"
for s in "${stacks[@]}"; do
    IFS='|' read -r _ _ services <<<"$s"
    for sp in $services; do
        now="$(processed "${sp##*:}")"
        rate="$(awk -v a="${first[$sp]:-0}" -v b="${now:-0}" -v t="$interval" 'BEGIN { printf "%.1f", (b - a) / t }')"
        echo "  ${sp%%:*}: ${first[$sp]:-?} -> ${now:-?} (${rate}/s)"
        if ! awk -v a="${first[$sp]:-0}" -v b="${now:-0}" 'BEGIN { exit !(b > a) }'; then
            echo "smoke.sh: FAIL: ${sp%%:*} processed nothing" >&2
            failed=1
        fi
    done
done
# A service that crashed and came back (restart policy) hides a start-up fault; count it.
for s in "${stacks[@]}"; do
    IFS='|' read -r project _ services <<<"$s"
    for sp in $services; do
        restarts="$(docker inspect -f '{{.RestartCount}}' "$(container_of "$project" "${sp%%:*}")")"
        if [[ "$restarts" != 0 ]]; then
            echo "smoke.sh: FAIL: ${sp%%:*} restarted $restarts times" >&2
            failed=1
        fi
    done
done
if [[ $monitoring -eq 1 ]]; then
    # Prometheus's targets API: every service's health "up" (it scrapes every 5 s).
    want=$((${#first[@]}))
    up=0
    for _ in $(seq 1 30); do
        up="$(curl -fsS "http://127.0.0.1:${PROMETHEUS_PORT:-9099}/api/v1/targets" 2>/dev/null |
            grep -o '"health":"up"' | wc -l || true)"
        [[ "$up" -ge "$want" ]] && break
        sleep 2
    done
    echo "smoke.sh: Prometheus targets up: $up of $want"
    curl -fsS "http://127.0.0.1:${PROMETHEUS_PORT:-9099}/api/v1/targets" |
        grep -o '"scrapeUrl":"[^"]*"\|"health":"[a-z]*"' | paste - - || true
    [[ "$up" -ge "$want" ]] || failed=1
fi
[[ $failed -eq 0 ]] || exit 1
echo "smoke.sh: PASS (no restarts)"
