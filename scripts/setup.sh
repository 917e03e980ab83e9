#!/usr/bin/env bash
# Installs what conesight needs on a fresh machine, idempotently, into build/.
#
#   scripts/setup.sh runtime   what running needs (`make demo`, `make images`): Debian packages
#                              (GStreamer with its base and good plugins among them),
#                              build/onnxruntime/libonnxruntime.so.1.31.1 (ONNX Runtime for `ort`,
#                              load-dynamic, taken from the PyPI wheel onnxruntime==1.31.1) and an
#                              empty build/venv whose pip fetches that wheel. No PyTorch.
#   scripts/setup.sh [all]     also the Python tools and the training stack in build/venv
#                              (scripts/requirements.txt, training/requirements.txt: PyTorch from
#                              PyPI, ~6 GB) for `make test`, `make lint`, `make eval`, training.
#
# Re-running is cheap: each step is skipped when its stamp matches its inputs.
set -euo pipefail
MODE="${1:-all}"
case "$MODE" in
  runtime | all) ;;
  *)
    echo "usage: scripts/setup.sh [runtime|all]  (got '$MODE')" >&2
    exit 2
    ;;
esac

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="$ROOT/build"
VENV="$BUILD/venv"
ORT_VERSION="1.31.1"
ORT_DIR="$BUILD/onnxruntime"
ORT_LIB="$ORT_DIR/libonnxruntime.so.$ORT_VERSION"
PYTHON="${PYTHON:-python3}"
mkdir -p "$BUILD"

log() { printf '[setup] %s\n' "$*"; }

# --- Debian packages (only what pip wheels and the Rust build cannot bring) -----------------
need_apt=()
command -v unzip >/dev/null 2>&1 || need_apt+=(unzip)
# openssl: deploy/certs.sh (the mTLS CA and node certificates) and its tests.
command -v openssl >/dev/null 2>&1 || need_apt+=(openssl)
"$PYTHON" -c 'import venv, ensurepip' >/dev/null 2>&1 || need_apt+=(python3-venv)
# GStreamer, for the camera sources `gst:PIPELINE` and `video:PATH` (the camera service and the
# CLI link it): headers and pkg-config to build, the base and good plugins to run (videotestsrc,
# videoconvert, decodebin, v4l2src, jpegdec, avidemux, ...), gst-launch-1.0 for the tests and for
# trying a camera pipeline by hand.
GST_PACKAGES=(pkg-config libgstreamer1.0-dev libgstreamer-plugins-base1.0-dev
  gstreamer1.0-plugins-base gstreamer1.0-plugins-good gstreamer1.0-tools)
if command -v dpkg-query >/dev/null 2>&1; then
  for pkg in "${GST_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed' || need_apt+=("$pkg")
  done
elif ! pkg-config --exists gstreamer-app-1.0 gstreamer-video-1.0 2>/dev/null \
  || ! command -v gst-launch-1.0 >/dev/null 2>&1; then
  need_apt+=("${GST_PACKAGES[@]}")
fi
# Prometheus and promtool (Debian's): the presence test scrapes the services with it,
# deploy/check.sh checks the alert rules, the image of compose's `monitoring` profile carries it.
if [ "$MODE" = all ] && ! { command -v prometheus && command -v promtool; } >/dev/null 2>&1; then
  need_apt+=(prometheus)
fi
# Chromium (Debian's): the dashboard test loads the page in it headless.
if [ "$MODE" = all ] && ! command -v chromium >/dev/null 2>&1; then
  need_apt+=(chromium)
fi
if [ ${#need_apt[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    log "installing Debian packages: ${need_apt[*]}"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_apt[@]}" >/dev/null
  else
    log "missing ${need_apt[*]}: install them with your package manager (e.g. sudo apt-get install ${need_apt[*]})"
    exit 1
  fi
fi

# --- Python virtual environment --------------------------------------------------------------
REQ="$ROOT/scripts/requirements.txt"
REQ_TRAIN="$ROOT/training/requirements.txt"
stamp_inputs="$( { cat "$REQ"; [ ! -f "$REQ_TRAIN" ] || cat "$REQ_TRAIN"; } | sha256sum | cut -c1-16)"
if [ ! -x "$VENV/bin/python" ]; then
  log "creating Python virtual environment in $VENV"
  "$PYTHON" -m venv "$VENV"
fi
if [ "$MODE" = all ] && [ "$(cat "$VENV/.stamp" 2>/dev/null)" != "$stamp_inputs" ]; then
  log "installing Python packages (scripts/requirements.txt, training/requirements.txt)"
  "$VENV/bin/python" -m pip install -q --upgrade pip
  "$VENV/bin/python" -m pip install -q -r "$REQ"
  if [ -f "$REQ_TRAIN" ]; then
    "$VENV/bin/python" -m pip install -q -r "$REQ_TRAIN"
  fi
  echo "$stamp_inputs" > "$VENV/.stamp"
fi

# --- ONNX Runtime shared library from the PyPI wheel -----------------------------------------
if [ ! -f "$ORT_LIB" ]; then
  log "fetching onnxruntime==$ORT_VERSION wheel for its shared library"
  tmp="$(mktemp -d)"
  trap 'rm -rf "$tmp"' EXIT
  "$VENV/bin/python" -m pip download -q --no-deps --only-binary=:all: -d "$tmp" "onnxruntime==$ORT_VERSION"
  wheel="$(ls "$tmp"/onnxruntime-*.whl)"
  mkdir -p "$ORT_DIR"
  unzip -q -o -j "$wheel" "onnxruntime/capi/libonnxruntime.so.$ORT_VERSION" -d "$ORT_DIR"
  log "ONNX Runtime library at $ORT_LIB"
fi

if [ "$MODE" = all ]; then
  log "ready: ORT_DYLIB_PATH=$ORT_LIB, Python at $VENV/bin/python"
else
  log "ready to run: ORT_DYLIB_PATH=$ORT_LIB (no Python packages: \`scripts/setup.sh all\` for tests and training)"
fi
