#!/usr/bin/env bash
# Static checks of deploy/ that need no Docker daemon and build nothing (CI-safe):
#   - every compose file and profile validates (`docker compose config -q`, or Debian's
#     docker-compose 1.x); skipped when neither is installed;
#   - every image a compose file names is a target of deploy/Dockerfile, and every Dockerfile
#     service target is built by build-images.sh;
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
