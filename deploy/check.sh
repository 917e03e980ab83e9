#!/usr/bin/env bash
# Static checks of deploy/ that need no Docker daemon and build nothing (CI-safe):
#   - every compose file and profile validates (`docker compose config -q`, or Debian's
#     docker-compose 1.x); skipped when neither is installed;
#   - every image a compose file names is a target of deploy/Dockerfile, and every Dockerfile
#     service target is built by build-images.sh;
#   - the Kubernetes manifests (deploy/k8s/) pass a schema check offline (kubernetes-validate
#     --strict, from scripts/requirements.txt; no cluster), and the Indexed Job's shard count
#     matches its completions;
#   - the swarm stack file (deploy/stack.replay.yml) passes `docker stack config` when the
#     Docker CLI has it (20.10 has not: then a YAML parse);
#   - the scripts are shellcheck-clean (when shellcheck is installed).
# Exit code 0 when all checks that could run passed.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

failures=0
fail() {
    echo "deploy/check.sh: FAIL: $*" >&2
    failures=$((failures + 1))
}
ok() { echo "deploy/check.sh: ok: $*"; }
skip() { echo "deploy/check.sh: skipped: $*"; }

# --- compose files --------------------------------------------------------------------------
compose=()
if command -v docker >/dev/null && docker compose version >/dev/null 2>&1; then
    compose=(docker compose)
elif command -v docker-compose >/dev/null; then
    compose=(docker-compose)
fi

# file|profile|extra environment
cases=(
    "docker-compose.yml||"
    "docker-compose.yml|tools|"
    "docker-compose.yml|monitoring|"
    "docker-compose.yml||CONESIGHT_CAMERA_FLAGS=--publish-boxes"
    "deploy/compose.split.yml|jetson|"
    "deploy/compose.split.yml|carpc|JETSON_ADDR=192.0.2.10"
    "docker-compose.yml:deploy/compose.mtls.yml||"
    "docker-compose.yml:deploy/compose.mtls.yml|tools|"
    "deploy/compose.split.yml:deploy/compose.split.mtls.yml|jetson|"
    "deploy/compose.split.yml:deploy/compose.split.mtls.yml|carpc|JETSON_ADDR=192.0.2.10"
)
if [[ ${#compose[@]} -eq 0 ]]; then
    skip "compose validation (no docker compose / docker-compose)"
else
    for c in "${cases[@]}"; do
        IFS='|' read -r file profile extra <<<"$c"
        # file may be BASE:OVERRIDE (an override such as deploy/compose.mtls.yml on its base).
        args=(-p conesight)
        IFS=':' read -r -a files <<<"$file"
        for f in "${files[@]}"; do args+=(-f "$f"); done
        [[ -n "$profile" ]] && args+=(--profile "$profile")
        if env ${extra:+"$extra"} "${compose[@]}" "${args[@]}" config -q; then
            ok "${compose[*]} config: $file ${profile:+(profile $profile)}"
        else
            fail "${compose[*]} config: $file ${profile:+(profile $profile)}"
        fi
    done
fi

# --- images named by compose vs Dockerfile targets --------------------------------------------
mapfile -t targets < <(sed -n 's/^FROM [^ ]* AS \([a-z]*\)$/\1/p' deploy/Dockerfile)
for file in docker-compose.yml deploy/compose.split.yml; do
    while read -r image; do
        [[ -z "$image" ]] && continue
        if [[ " ${targets[*]} " == *" $image "* ]]; then
            ok "$file: conesight/$image is a Dockerfile target"
        else
            fail "$file names conesight/$image, not a target of deploy/Dockerfile (${targets[*]})"
        fi
    done < <(sed -n 's|^ *image: conesight/\([a-z]*\):.*|\1|p' "$file" | sort -u)
done
for t in "${targets[@]}"; do
    [[ "$t" == runtime ]] && continue
    if grep -q "\[$t\]=" deploy/build-images.sh; then
        ok "build-images.sh builds target $t"
    else
        fail "deploy/Dockerfile target $t is not built by deploy/build-images.sh"
    fi
done

# --- Zenoh configs the images point at --------------------------------------------------------
for f in deploy/zenoh/peer.json5 deploy/zenoh/router.json5; do
    if [[ -f "$f" ]]; then ok "$f present"; else fail "$f missing"; fi
done

# --- Prometheus config and alert rules --------------------------------------------------------
if command -v promtool >/dev/null; then
    if promtool check config deploy/prometheus/prometheus.yml >/dev/null \
        && promtool check rules deploy/prometheus/alerts.yml \
        && promtool test rules deploy/prometheus/alerts_test.yml; then
        ok "promtool: deploy/prometheus config, rules and rule tests"
    else
        fail "promtool: deploy/prometheus config, rules or rule tests"
    fi
else
    skip "promtool (not installed: apt-get install prometheus)"
fi
if python3 -m json.tool deploy/grafana/conesight-dashboard.json >/dev/null; then
    ok "deploy/grafana/conesight-dashboard.json is JSON"
else
    fail "deploy/grafana/conesight-dashboard.json is not JSON"
fi

# --- Kubernetes manifests and the swarm stack --------------------------------------------------
py="$ROOT/build/venv/bin/python"
[[ -x "$py" ]] || py=python3
kv="$ROOT/build/venv/bin/kubernetes-validate"
[[ -x "$kv" ]] || kv="$(command -v kubernetes-validate || true)"
# The oldest Kubernetes with everything the Job uses (backoffLimitPerIndex: beta in 1.29) and
# the newest the validator knows.
for version in 1.29.0 1.37.0; do
    if [[ -z "$kv" ]]; then
        skip "kubernetes-validate (not installed: scripts/setup.sh all installs it)"
        break
    elif "$kv" --strict --quiet -k "$version" deploy/k8s/*.yaml; then
        ok "kubernetes-validate --strict -k $version deploy/k8s/*.yaml"
    else
        fail "kubernetes-validate --strict -k $version deploy/k8s/*.yaml"
    fi
done
if "$py" - deploy/k8s/replay-job.yaml <<'EOF'
import sys
import yaml
docs = [d for d in yaml.safe_load_all(open(sys.argv[1])) if d]
job = next(d for d in docs if d["kind"] == "Job")
spec = job["spec"]
claims = {d["metadata"]["name"] for d in docs if d["kind"] == "PersistentVolumeClaim"}
pod = spec["template"]["spec"]
args = pod["containers"][0]["args"]
assert spec["completionMode"] == "Indexed", "completionMode must be Indexed"
count = int(args[args.index("--shard-count") + 1])
assert count == spec["completions"], f"--shard-count {count} != completions {spec['completions']}"
assert "--shard-index" not in args, "the index comes from JOB_COMPLETION_INDEX"
assert pod["restartPolicy"] == "Never", "restartPolicy Never (retries per index)"
volumes = {v["persistentVolumeClaim"]["claimName"] for v in pod["volumes"] if "persistentVolumeClaim" in v}
assert volumes <= claims, f"claims {volumes - claims} not in the file"
EOF
then
    ok "deploy/k8s/replay-job.yaml: Indexed, --shard-count = completions, PVC declared"
else
    fail "deploy/k8s/replay-job.yaml: Indexed Job consistency"
fi
if command -v docker >/dev/null && docker stack config --help >/dev/null 2>&1; then
    if CONESIGHT_JOB_DATA=/srv/conesight docker stack config -c deploy/stack.replay.yml >/dev/null; then
        ok "docker stack config: deploy/stack.replay.yml"
    else
        fail "docker stack config: deploy/stack.replay.yml"
    fi
elif "$py" -c 'import sys, yaml; d = yaml.safe_load(open(sys.argv[1])); r = d["services"]["replay"]; assert r["deploy"]["restart_policy"]["condition"] == "on-failure"; assert "{{.Task.Slot}}" in r["environment"]["CONESIGHT_SHARD_SLOT"]' deploy/stack.replay.yml; then
    ok "deploy/stack.replay.yml parses (restart on-failure, task slot as shard; no docker stack config here)"
else
    fail "deploy/stack.replay.yml"
fi

# --- scripts ----------------------------------------------------------------------------------
if command -v shellcheck >/dev/null; then
    if shellcheck deploy/*.sh deploy/zenoh/*.sh deploy/arm64/*.sh; then ok "shellcheck deploy/*.sh deploy/zenoh/*.sh deploy/arm64/*.sh"; else fail "shellcheck deploy/*.sh deploy/zenoh/*.sh deploy/arm64/*.sh"; fi
else
    skip "shellcheck (not installed)"
fi

if [[ $failures -gt 0 ]]; then
    echo "deploy/check.sh: $failures check(s) failed" >&2
    exit 1
fi
echo "deploy/check.sh: all checks passed"
