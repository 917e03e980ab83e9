#!/usr/bin/env bash
# Builds the service images from binaries compiled on the host (no Rust toolchain in Docker):
#
#   deploy/build-images.sh                  # base if missing, cargo build --release, all images
#   deploy/build-images.sh --no-cargo       # reuse target/release binaries as they are
#   deploy/build-images.sh camera localiser # only these targets (camera detector keypoints localiser cli prometheus)
#   deploy/build-images.sh --release bookworm  # base release on a non-Debian host (default: the host's)
#   CONESIGHT_BIN_DIR=target/debug deploy/build-images.sh --no-cargo cli  # image debug binaries (tests)
#   deploy/build-images.sh --arch arm64     # Jetson images from deploy/arm64/ (make image-arm64)
#
# Images: conesight/<target>:latest and conesight/<target>:<git short rev> (arm64: :arm64 and
# :<rev>-arm64, binaries cross-compiled by deploy/arm64/cross-build.sh on a trixie base). The build context is
# staged in build/images/context/ (git-ignored) so Docker never sees target/ or the venv.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

ALL_TARGETS=(camera detector keypoints localiser cli)
# target -> cargo package and binary
declare -A PACKAGE=(
    [camera]=conesight-camera-service
    [detector]=conesight-detector-service
    [keypoints]=conesight-keypoints-service
    [localiser]=conesight-localiser-service
    [cli]=conesight-cli
)
declare -A BINARY=(
    [camera]=conesight-camera
    [detector]=conesight-detector
    [keypoints]=conesight-keypoints
    [localiser]=conesight-localiser
    [cli]=conesight
)
# Targets that copy a Debian program of the host instead of a cargo binary.
declare -A HOST_PROGRAM=(
    [prometheus]=/usr/bin/prometheus
)
ORT_LIB="build/onnxruntime/libonnxruntime.so.1.31.1"

run_cargo=1
release=""
arch=""
targets=()
while [[ $# -gt 0 ]]; do
    arg="$1"
    case "$arg" in
        --no-cargo) run_cargo=0 ;;
        --release) release="$2"; shift ;;
        --arch) arch="$2"; shift ;;
        -h | --help) sed -n '2,10p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
        -*) echo "build-images.sh: unknown option $arg" >&2; exit 2 ;;
        *)
            if [[ -z "${PACKAGE[$arg]:-}" && -z "${HOST_PROGRAM[$arg]:-}" ]]; then
                echo "build-images.sh: unknown target $arg (one of ${ALL_TARGETS[*]} ${!HOST_PROGRAM[*]})" >&2
                exit 2
            fi
            targets+=("$arg")
            ;;
    esac
    shift
done
[[ ${#targets[@]} -eq 0 ]] && targets=("${ALL_TARGETS[@]}")

if [[ -z "$release" ]]; then
    # shellcheck disable=SC1091
    release="$(. /etc/os-release; if [[ "${ID:-}" == debian ]]; then echo "${VERSION_CODENAME:-}"; fi)"
fi
if [[ -z "$release" ]]; then
    echo "build-images.sh: the host is not Debian; pass --release (e.g. --release bookworm)" >&2
    exit 2
fi
bin_dir="${CONESIGHT_BIN_DIR:-target/release}"
tag_suffix=""
tag_latest=latest
platform=()
base="conesight/base:${release}"
if [[ -n "$arch" && "$arch" != "$(dpkg --print-architecture)" ]]; then
    [[ "$arch" == arm64 ]] || { echo "build-images.sh: --arch arm64 is the only foreign one" >&2; exit 2; }
    # The cross toolchain links trixie's arm64 glibc, so the base is trixie whatever the host.
    release="${CONESIGHT_ARM64_RELEASE:-trixie}"
    base="conesight/base:${release}-arm64"
    bin_dir="target/aarch64-cross/aarch64-unknown-linux-gnu/release"
    ORT_LIB="build/arm64/onnxruntime/libonnxruntime.so.1.31.1"
    tag_suffix="-arm64"
    tag_latest=arm64
    platform=(--platform linux/arm64)
    deploy/arm64/onnxruntime.sh
    deploy/build-base.sh --release "$release" --arch arm64
else
    deploy/build-base.sh --release "$release"
fi

if [[ ! -f "$ORT_LIB" ]]; then
    echo "build-images.sh: $ORT_LIB missing; run 'make setup' first" >&2
    exit 1
fi

# The legacy builder stages every target before the one asked for, so the context always
# holds all binaries; build them all with one cargo call (one lock, one dependency graph).
if [[ $run_cargo -eq 1 ]]; then
    pkgs=()
    for t in "${ALL_TARGETS[@]}"; do pkgs+=(-p "${PACKAGE[$t]}"); done
    if [[ -n "$tag_suffix" ]]; then
        deploy/arm64/cross-build.sh "${pkgs[@]}"
    else
        echo "build-images.sh: cargo build --release ${pkgs[*]}"
        cargo build --release "${pkgs[@]}"
    fi
fi

ctx="build/images/context${tag_suffix}"
rm -rf "$ctx"
mkdir -p "$ctx/bin" "$ctx/onnxruntime" "$ctx/models" "$ctx/zenoh"
for t in "${ALL_TARGETS[@]}"; do
    bin="$bin_dir/${BINARY[$t]}"
    if [[ ! -x "$bin" ]]; then
        echo "build-images.sh: $bin missing (cargo build --release -p ${PACKAGE[$t]})" >&2
        exit 1
    fi
    cp "$bin" "$ctx/bin/"
done
# Debuginfo off (the release profile keeps it for backtraces; images stay small). The host's
# strip reads only its own architecture, so arm64 binaries take binutils-aarch64-linux-gnu's.
strip_tool="strip"
if [[ -n "$tag_suffix" ]]; then
    strip_tool=aarch64-linux-gnu-strip
    command -v "$strip_tool" >/dev/null ||
        DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends binutils-aarch64-linux-gnu
fi
"$strip_tool" --strip-debug "$ctx"/bin/*
cp "$ORT_LIB" "$ctx/onnxruntime/"
shopt -s nullglob
# Only the models the services run (and their cards), fp32 and int8 (`--precision`; the
# default `auto` runs the int8 keypoint network): the paper baseline and the ablation (20 MB)
# are for `make eval`, not for a car.
for model in detector keypoints; do
    cp "models/$model.onnx" "models/$model.card.json" "models/$model.md" \
        "models/$model.int8.onnx" "models/$model.int8.card.json" "$ctx/models/"
done
cp models/README.md "$ctx/models/"
cp deploy/zenoh/*.json5 "$ctx/zenoh/"
mkdir -p "$ctx/prometheus"
cp deploy/prometheus/prometheus.yml deploy/prometheus/alerts.yml "$ctx/prometheus/"
for t in "${targets[@]}"; do
    program="${HOST_PROGRAM[$t]:-}"
    [[ -z "$program" ]] && continue
    if [[ ! -x "$program" ]]; then
        echo "build-images.sh: $program missing (apt-get install $t, or scripts/setup.sh)" >&2
        exit 1
    fi
    cp "$program" "$ctx/prometheus/"
done
shopt -u nullglob

# Docker CLIs from 23 on use BuildKit through buildx; without the buildx plugin (as on our
# machines) the classic builder does the job.
if ! docker buildx version >/dev/null 2>&1; then
    export DOCKER_BUILDKIT=0
fi

rev="$(git rev-parse --short HEAD 2>/dev/null || echo unknown)"
for t in "${targets[@]}"; do
    echo "build-images.sh: conesight/$t"
    docker build --quiet "${platform[@]}" \
        --file deploy/Dockerfile \
        --build-arg "BASE=$base" \
        --target "$t" \
        --label "org.opencontainers.image.revision=$rev" \
        --label "org.opencontainers.image.source=conesight" \
        --tag "conesight/$t:$tag_latest" \
        --tag "conesight/$t:$rev$tag_suffix" \
        "$ctx"
done

docker image ls --format 'table {{.Repository}}:{{.Tag}}\t{{.Size}}' "conesight/*:$tag_latest"
