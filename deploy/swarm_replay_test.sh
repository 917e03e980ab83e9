#!/usr/bin/env bash
# Replay jobs on a single-node Docker Swarm (deploy/stack.replay.yml), started and torn down here:
#
#   deploy/swarm_replay_test.sh               # 6 recordings, 2 replicas; then again with one task killed
#   deploy/swarm_replay_test.sh --throughput  # also 1 replica, and the two rates side by side
#
# 1. Records 6 short synthetic drives (distinct seeds) with the host's `conesight` ($CONESIGHT_BIN,
#    default target/debug/conesight, else target/release/conesight).
# 2. `docker swarm init` if the swarm is inactive (left again at the end), `docker stack deploy`
#    with 2 replicas; waits until every task is Complete; checks 6 results and 6 summaries, each
#    drive exactly once, by the shard its list index belongs to, no partial file left, and one
#    aggregate report (`conesight aggregate --expect 6`).
# 3. Again, `docker kill` of one task's container while its shard still has drives to do: swarm
#    restarts it (restart_policy on-failure), and the outcome is the same: 6 results, and
#    `conesight aggregate --baseline` of the first run reports zero change.
# Skips (exit 0, with a message) when Docker or the image ($CONESIGHT_JOB_IMAGE, default
# conesight/cli:latest, with the `job` subcommand) is missing. Needs about 5 minutes on 2 cores.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

STACK=conesight-replay-test
SERVICE="${STACK}_replay"
IMAGE="${CONESIGHT_JOB_IMAGE:-conesight/cli:latest}"
DRIVES=6
FRAMES="${CONESIGHT_TEST_FRAMES:-20}"
throughput=0
[[ "${1:-}" == "--throughput" ]] && throughput=1

skip() {
    echo "swarm_replay_test.sh: SKIP: $*"
    exit 0
}
fail() {
    echo "swarm_replay_test.sh: FAIL: $*" >&2
    exit 1
}

command -v docker >/dev/null 2>&1 || skip "no docker CLI on the PATH"
docker info >/dev/null 2>&1 || skip "the Docker daemon does not answer (docker info)"
docker image inspect "$IMAGE" >/dev/null 2>&1 \
    || skip "no image $IMAGE: build it with deploy/build-images.sh cli (or CONESIGHT_BIN_DIR=target/debug deploy/build-images.sh --no-cargo cli)"
docker run --rm "$IMAGE" job --help >/dev/null 2>&1 \
    || skip "$IMAGE has no 'job' subcommand: rebuild it (deploy/build-images.sh cli)"
BIN="${CONESIGHT_BIN:-}"
if [[ -z "$BIN" ]]; then
    for candidate in target/debug/conesight target/release/conesight; do
        [[ -x "$candidate" ]] && BIN="$candidate" && break
    done
fi
[[ -n "$BIN" && -x "$BIN" ]] || skip "no host conesight binary (cargo build -p conesight-cli, or set CONESIGHT_BIN)"
export ORT_DYLIB_PATH="${ORT_DYLIB_PATH:-$ROOT/build/onnxruntime/libonnxruntime.so.1.31.1}"

work="$(mktemp -d "${TMPDIR:-/tmp}/conesight-swarm.XXXXXX")"
swarm_was="$(docker info --format '{{.Swarm.LocalNodeState}}')"
cleanup() {
    docker stack rm "$STACK" >/dev/null 2>&1 || true
    for _ in $(seq 60); do
        [[ -z "$(docker ps -aq --filter "label=com.docker.stack.namespace=$STACK")" ]] && break
        sleep 1
    done
    if [[ "$swarm_was" == inactive ]]; then
        docker swarm leave --force >/dev/null 2>&1 || true
    fi
    rm -rf "$work"
}
trap cleanup EXIT

# 1. Recordings.
mkdir -p "$work/data/recordings"
echo "recording $DRIVES drives of $FRAMES frames with $BIN"
for i in $(seq 0 $((DRIVES - 1))); do
    port=$((17600 + i))
    ns="swarmrec$$x$i"
    "$BIN" record --namespace "$ns" --zenoh-listen "tcp/127.0.0.1:$port" \
        --out "$work/data/recordings/drive_$i.mcap" --queue-len 64 >"$work/record_$i.log" 2>&1 &
    recorder=$!
    sleep 1
    "$BIN" run --services camera --namespace "$ns" --zenoh-connect "tcp/127.0.0.1:$port" \
        --zenoh-listen tcp/127.0.0.1:0 --frames "$FRAMES" --rate-hz 10 --seed $((100 + i)) \
        --frame-encoding jpeg --preload 5 --out "$work/camera_$i" >"$work/camera_$i.log" 2>&1 \
        || fail "camera of drive $i: $(tail -5 "$work/camera_$i.log")"
    sleep 0.5
    kill -INT "$recorder"
    wait "$recorder" || fail "recorder of drive $i: $(tail -5 "$work/record_$i.log")"
done
ls -l "$work/data/recordings"

if [[ "$swarm_was" == inactive ]]; then
    echo "docker swarm init (left again at the end)"
    docker swarm init --advertise-addr 127.0.0.1 >/dev/null
fi

count() { find "$1" -maxdepth 1 -name "$2" | wc -l; }

# deploy RESULTS_NAME REPLICAS KILL(0|1): one stack run into $work/data/<RESULTS_NAME>; prints
# the wall time in seconds on fd 3.
deploy() {
    local name="$1" replicas="$2" kill_one="$3"
    local results="$work/data/$name"
    rm -rf "$work/data/results"
    mkdir -p "$work/data/results"
    local started killed=""
    started=$(date +%s.%N)
    CONESIGHT_JOB_IMAGE="$IMAGE" CONESIGHT_JOB_DATA="$work/data" CONESIGHT_REPLICAS="$replicas" \
        CONESIGHT_UID="$(id -u)" CONESIGHT_GID="$(id -g)" \
        docker stack deploy -c deploy/stack.replay.yml "$STACK" >/dev/null
    local deadline=$((SECONDS + 900))
    while true; do
        ((SECONDS < deadline)) || fail "$name: not done after 15 min: $(docker service ps --no-trunc "$SERVICE")"
        local done_now running
        done_now=$(count "$work/data/results" '*.summary.json')
        running=$(docker ps -q --filter "label=com.docker.swarm.service.name=$SERVICE" | wc -l)
        if [[ "$kill_one" == 1 && -z "$killed" && "$done_now" -ge 1 ]]; then
            # A running task whose shard still has drives to do (slot s has list indices
            # s-1, s-1+N, ...; summaries say which are done).
            for id in $(docker ps -q --filter "label=com.docker.swarm.service.name=$SERVICE"); do
                local task slot mine left
                task=$(docker inspect --format '{{index .Config.Labels "com.docker.swarm.task.name"}}' "$id")
                slot=$(echo "$task" | cut -d. -f2)
                mine=$(( (DRIVES - slot + replicas) / replicas ))
                left=$mine
                for f in "$work/data/results"/*.summary.json; do
                    grep -q "\"index\": $((slot - 1))," "$f" && left=$((left - 1))
                done
                if ((left > 0)); then
                    echo "$name: docker kill $task (slot $slot, $left of its $mine drives to do)"
                    docker kill "$id" >/dev/null
                    killed="$slot"
                    break
                fi
            done
        fi
        local states
        states=$(docker service ps --format '{{.DesiredState}} {{.CurrentState}}' "$SERVICE" 2>/dev/null || true)
        if [[ "$done_now" -ge "$DRIVES" && "$running" -eq 0 ]] \
            && ! grep -q '^Running' <<<"$states"; then
            break
        fi
        sleep 1
    done
    local wall
    wall=$(echo "$(date +%s.%N) - $started" | bc)
    docker service ps --format '{{.Name}} {{.CurrentState}} {{.Error}}' "$SERVICE" | sed "s/^/$name: task /"
    local restarts
    restarts=$(docker service ps -q "$SERVICE" | wc -l)
    docker stack rm "$STACK" >/dev/null
    for _ in $(seq 60); do
        [[ -z "$(docker ps -aq --filter "label=com.docker.stack.namespace=$STACK")" ]] && break
        sleep 1
    done
    rm -rf "$results"
    mv "$work/data/results" "$results"

    # Exactly once: 6 results and 6 summaries, one per recording, from the right shard.
    [[ $(count "$results" '*.cones.mcap') -eq $DRIVES ]] || fail "$name: $(count "$results" '*.cones.mcap') results, expected $DRIVES"
    [[ $(count "$results" '*.summary.json') -eq $DRIVES ]] || fail "$name: $(count "$results" '*.summary.json') summaries"
    [[ $(count "$results" '.*.partial') -eq 0 ]] || fail "$name: partial files left: $(ls -a "$results")"
    python3 - "$results" "$replicas" "$DRIVES" <<'EOF' || fail "$name: summaries do not add up"
import json, pathlib, sys
results, replicas, drives = pathlib.Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
summaries = [json.loads(p.read_text()) for p in sorted(results.glob("*.summary.json"))]
names = sorted(s["drive"] for s in summaries)
assert names == [f"drive_{i}" for i in range(drives)], names
for s in summaries:
    assert s["list_index"] % replicas == s["shard"]["index"], s
    assert s["shard"]["count"] == replicas, s
    assert s["frames"] > 0 and s["frames_lost"] == 0, s
    assert (results / s["results"]).is_file(), s
EOF
    "$BIN" aggregate "$results" --expect "$DRIVES" >"$work/$name.aggregate.txt" \
        || fail "$name: aggregate: $(cat "$work/$name.aggregate.txt")"
    [[ -f "$results/aggregate.json" ]] || fail "$name: no aggregate.json"
    sed "s/^/$name: /" "$work/$name.aggregate.txt"
    if [[ "$kill_one" == 1 ]]; then
        [[ -n "$killed" ]] || fail "$name: no task was killed (the job ended before a kill)"
        ((restarts > replicas)) || fail "$name: swarm did not restart the killed task ($restarts tasks)"
        echo "$name: killed slot $killed; $restarts tasks in all (swarm restarted it)"
    fi
    echo "$name $replicas $wall" >&3
}

exec 3>"$work/times.txt"
deploy run2 2 0
deploy run2_killed 2 1
"$BIN" aggregate "$work/data/run2_killed" --baseline "$work/data/run2" --json >"$work/compare.json"
python3 - "$work/compare.json" <<'EOF' || fail "the killed run's cones differ from the first run's"
import json, sys
report = json.load(open(sys.argv[1]))
base = report["baseline"]
assert base["zero_change"], base
assert not base["only_in_results"] and not base["only_in_baseline"], base
print(f"run2_killed vs run2: {len(base['drives'])} drives, {base['frames_compared']} frames compared, zero change")
EOF
if [[ $throughput == 1 ]]; then
    deploy run1 1 0
fi
exec 3>&-

echo
echo "workers  wall_s  recordings/min  frames/s (all $DRIVES drives, $FRAMES frames each, from deploy to done)"
while read -r name replicas wall; do
    frames=$(python3 -c "import json,pathlib;print(sum(json.loads(p.read_text())['frames'] for p in pathlib.Path('$work/data/$name').glob('*.summary.json')))")
    python3 -c "print(f'{$replicas:>7}  {$wall:>6.1f}  {$DRIVES*60/$wall:>14.2f}  {$frames/$wall:>8.2f}   $name')"
done <"$work/times.txt"
echo "swarm_replay_test.sh: PASS"
