#!/usr/bin/env bash
# Prints the RLIMIT_MEMLOCK the compose files should ask for (CONESIGHT_MEMLOCK): -1 (unlimited,
# what Zenoh's shared memory wants) when this Docker daemon may raise the limit, else Docker's
# default of 8 MiB, which a daemon without CAP_SYS_RESOURCE (rootless, sandboxed) still accepts.
# Probes with a throwaway container of the camera image (or the base when that is missing).
#
#   CONESIGHT_MEMLOCK=$(deploy/memlock.sh) docker-compose -p conesight up -d
set -euo pipefail

image="conesight/camera:${CONESIGHT_TAG:-latest}"
if ! docker image inspect "$image" >/dev/null 2>&1; then
    image="$(docker image ls --format '{{.Repository}}:{{.Tag}}' conesight/base | head -n1)"
fi
if [[ -n "$image" ]] &&
    docker run --rm --ulimit memlock=-1:-1 --entrypoint /bin/true "$image" >/dev/null 2>&1; then
    echo -1
else
    echo 8388608
fi
