#!/usr/bin/env bash
# ONNX Runtime for aarch64: libonnxruntime.so from the PyPI wheel onnxruntime==1.31.1 for
# manylinux aarch64 (CPU only; a Jetson's GPU needs NVIDIA's build, deploy/README.md "Jetson").
# Into build/arm64/onnxruntime/, skipped when present. Uses the venv of scripts/setup.sh.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
ORT_VERSION="1.31.1"
dir="$ROOT/build/arm64/onnxruntime"
lib="$dir/libonnxruntime.so.$ORT_VERSION"
[[ -f "$lib" ]] && { echo "onnxruntime.sh: $lib exists"; exit 0; }

python="$ROOT/build/venv/bin/python"
[[ -x "$python" ]] || "$ROOT/scripts/setup.sh" runtime
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
"$python" -m pip download -q --no-deps --only-binary=:all: \
    --platform manylinux2014_aarch64 --platform manylinux_2_28_aarch64 \
    -d "$tmp" "onnxruntime==$ORT_VERSION"
wheel="$(ls "$tmp"/onnxruntime-*aarch64*.whl)"
mkdir -p "$dir"
unzip -q -o -j "$wheel" "onnxruntime/capi/libonnxruntime.so.$ORT_VERSION" -d "$dir"
echo "onnxruntime.sh: $(basename "$wheel") -> $lib"
file "$lib" 2>/dev/null || true
