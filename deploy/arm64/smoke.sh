#!/usr/bin/env bash
# The arm64 image's `conesight` under qemu-user, against the x86 binary on the same image:
# `--version`, then `predict` on docs/sample/frame.jpg with the fp32 networks, the default mix
# (`auto`) and the int8 networks, and the cones compared per precision (each matched to one of
# the same class, positions within 1e-3 of the range for fp32, looser where int8 kernels run:
# see below; compare.py prints the largest differences).
#
#   deploy/arm64/smoke.sh              # in the conesight/cli:arm64 container (docker + binfmt)
#   deploy/arm64/smoke.sh --no-docker  # the cross-built binary on the arm64 rootfs (qemu -L)
# x86 side: $CONESIGHT_X86_BIN, else target/release/conesight, else target/debug/conesight.
# The emulated CPU is a Cortex-A76 (ARMv8.2 with dot product, no SVE/SME: the nearest qemu has to
# a Jetson Orin's Cortex-A78AE); CONESIGHT_QEMU_CPU=max gives every extension qemu knows.
# Outputs in build/arm64/smoke/. qemu (>= 8.1) and binfmt are set up by qemu.sh (root).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$ROOT"
use_docker=1
[[ "${1:-}" == "--no-docker" ]] && use_docker=0
out="build/arm64/smoke"
mkdir -p "$out"
image="docs/sample/frame.jpg"
camera="docs/sample/camera.yaml"

deploy/arm64/qemu.sh
export QEMU_CPU="${CONESIGHT_QEMU_CPU:-cortex-a76}"

x86="${CONESIGHT_X86_BIN:-}"
if [[ -z "$x86" ]]; then
    for candidate in target/release/conesight target/debug/conesight; do
        [[ -x "$candidate" ]] && { x86="$candidate"; break; }
    done
fi
if [[ -z "$x86" ]]; then
    cargo build --release -p conesight-cli
    x86=target/release/conesight
fi

if [[ $use_docker -eq 1 ]]; then
    arm=(docker run --rm --platform linux/arm64 -e QEMU_CPU -v "$ROOT/docs/sample:/sample:ro"
        --entrypoint /opt/conesight/bin/conesight conesight/cli:arm64)
    arm_image="/sample/frame.jpg"
    arm_camera="/sample/camera.yaml"
else
    rootfs="build/base/${CONESIGHT_ARM64_RELEASE:-trixie}-arm64/rootfs"
    arm=(env ORT_DYLIB_PATH="$ROOT/build/arm64/onnxruntime/libonnxruntime.so.1.31.1"
        build/arm64/qemu/qemu-aarch64 -L "$rootfs"
        target/aarch64-cross/aarch64-unknown-linux-gnu/release/conesight)
    arm_image="$image"
    arm_camera="$camera"
fi

echo "smoke.sh: qemu CPU $QEMU_CPU"
echo "smoke.sh: arm64 --version: $("${arm[@]}" --version)"
[[ $use_docker -eq 0 ]] && echo "smoke.sh: $(file -L "${arm[-1]}")"

# The fp32 networks, the default `auto` (int8 keypoints, fp32 detector) and both int8 copies
# (`--precision int8`: models/*.int8.onnx, which run on other kernels on each architecture).
status=0
for precision in fp32 auto int8; do
    start=$(date +%s%N)
    "${arm[@]}" predict --precision "$precision" --camera "$arm_camera" "$arm_image" \
        >"$out/arm64-$precision.jsonl"
    arm_ms=$((($(date +%s%N) - start) / 1000000))
    start=$(date +%s%N)
    "$x86" predict --precision "$precision" --camera "$camera" "$image" >"$out/x86-$precision.jsonl"
    x86_ms=$((($(date +%s%N) - start) / 1000000))
    echo "smoke.sh: $precision: predict took ${arm_ms} ms under qemu (arm64), ${x86_ms} ms native ($x86)"
    # fp32: the same arithmetic, so the same cones to 1e-3 of the range. Int8 networks run on
    # each CPU's own integer kernels (measured 2026-12-07 on docs/sample/frame.jpg, x86 AVX2
    # against arm64 under qemu, 7-bit keypoint weights): `auto` (int8 keypoints behind the fp32
    # detector) within 1.4e-7 of the range with the shipped detector, but 1.24e-3 on one 14 m
    # cone with a retrained one (its boxes, hence other crops), so auto is held to 1 % of the
    # range with the fp32 detector's exact scores; `int8` (the int8 detector too) within 0.46 %
    # of the range, scores within 0.015 (8.3 % and one cone lost with 8-bit keypoint weights;
    # 3.2 % with the retrained detector), so it is held to 10 % of the range, 0.05 in score,
    # and may lose cones within 0.05 of the threshold.
    tolerance=()
    [[ $precision == auto ]] && tolerance=(--rel 0.01)
    [[ $precision == int8 ]] && tolerance=(--rel 0.1 --score 0.05 --threshold-band 0.05)
    python3 deploy/arm64/compare.py "${tolerance[@]}" "$out/x86-$precision.jsonl" \
        "$out/arm64-$precision.jsonl" || status=1
done
exit $status
