# conesight: the two commands a fresh machine needs are `make demo` and `make test`.
# Both run scripts/setup.sh first (idempotent, cached in build/): `make demo` only what running
# needs (Debian packages, the ONNX Runtime library from the onnxruntime==1.31.1 wheel; no
# PyTorch), `make test` also the Python tools and the training stack in build/venv.

SHELL := /bin/bash
ROOT := $(CURDIR)
PY := $(ROOT)/build/venv/bin/python
export ORT_DYLIB_PATH ?= $(ROOT)/build/onnxruntime/libonnxruntime.so.1.31.1

.PHONY: setup setup-runtime demo demo-geometry test test-rust test-python lint bench bench-pnp bench-pipeline bench-detector quantize clean

setup:
	@bash scripts/setup.sh all

setup-runtime:
	@bash scripts/setup.sh runtime

## The main job on the embedded defaults: the four services in one process over an embedded
## Zenoh session on a synthetic sequence (live table, annotated frames and bird's-eye views in
## out/run/).
demo: setup-runtime
	cargo build --release -p conesight-cli
	./target/release/conesight run

## The geometry demo (cone PnP on exact keypoints, one rendered frame), PNGs in out/demo/.
demo-geometry: setup-runtime
	cargo build --release -p conesight-cli
	./target/release/conesight demo

## Every test: Rust (unit, property, integration) and Python.
test: setup
	cargo test --workspace
	PROFILE=debug bash scripts/on_your_car.sh
	$(MAKE) --no-print-directory test-python

test-python: setup
	@status=0; $(PY) -m pytest -q training bench || status=$$?; \
	  if [ $$status -eq 5 ]; then echo "pytest: no Python tests collected"; status=0; fi; exit $$status

lint: setup
	cargo fmt --all -- --check
	cargo clippy --workspace --all-targets -- -D warnings
	$(PY) -m ruff check training bench scripts
	$(PY) -m ruff format --check training bench scripts
	deploy/check.sh

## Criterion benchmarks (hot paths).
bench:
	cargo bench --workspace

## Our cone PnP against OpenCV's solvePnP variants on the same 10,000 correspondences.
bench-pnp: setup
	cargo build --release -p conesight-core --example pnp_bench
	$(PY) bench/pnp_vs_opencv.py --bench-bin target/release/examples/pnp_bench

## Our detector against the Ultralytics YOLO11n peer on the real test frames (mAP per class,
## recall by box height, ms per 1920x1200 frame): docs/detector-benchmark.md. The peer is
## trained first by bench/yolo_peer_train.py (see docs/detector-benchmark.md).
PEER ?= build/peer/yolo11n/weights/best.onnx
bench-detector: setup
	$(PY) bench/detector_vs_yolo.py --ours models/detector.onnx --peer $(PEER) \
	  --markdown build/detector-benchmark.md --json build/detector-benchmark.json

## Int8 copies of the shipped networks (issue 42): models/detector.int8.onnx and
## models/keypoints.int8.onnx with their cards, calibrated on real training frames and crops,
## measured against fp32 on the real test frames and validation crops, then timed side by side
## (training/conesight_train/quantize.py, bench_precision.py). Needs ../shared; ~8 minutes.
REAL_DATA := ../shared/data
quantize: setup
	PYTHONPATH=training $(PY) -m conesight_train.quantize detector \
	  --model models/detector.onnx --out models/detector.int8.onnx \
	  --calibration yolo:$(REAL_DATA)/real-train/fsoco-boxes/train \
	  --evaluate test=yolo:$(REAL_DATA)/real-train/fsoco-boxes/test \
	  --evaluate valid=yolo:$(REAL_DATA)/real-train/fsoco-boxes/valid --exclude first --reduce-range
	PYTHONPATH=training $(PY) -m conesight_train.quantize keypoints \
	  --model models/keypoints.onnx --out models/keypoints.int8.onnx \
	  --calibration real:$(REAL_DATA)/real-train/amz-keypoint-crops-hires:train \
	  --calibration real:$(REAL_DATA)/real-train/tuwr-keypoint-crops:train \
	  --calibration real:$(REAL_DATA)/real-dev/fsoco-keypoint-crops:train \
	  --evaluate amz_val=real:$(REAL_DATA)/real-dev/fsoco-keypoint-crops:val \
	  --evaluate hires_val=real:$(REAL_DATA)/real-train/amz-keypoint-crops-hires:val \
	  --evaluate tuwr_val=real:$(REAL_DATA)/real-train/tuwr-keypoint-crops:val --reduce-range
	PYTHONPATH=training $(PY) -m conesight_train.bench_precision --threads 1 2 --cards

## In-process vs over Zenoh (4 processes): per-stage latency, 2-30 Hz sweep with frames dropped,
## bus cost ratio; fp32, int8 and the default `auto` models side by side (~13 minutes).
bench-pipeline: setup
	cargo build --release -p conesight-e2e
	./target/release/pipeline-bench

clean:
	rm -rf build target

## Container images and the one-host compose stack (deploy/README.md). Not part of `make test`.
DEPLOY_COMPOSE ?= $(shell docker compose version >/dev/null 2>&1 && echo "docker compose" || echo docker-compose)
.PHONY: images compose-up compose-down deploy-check image-arm64 smoke-arm64

images: setup-runtime
	deploy/build-images.sh

compose-up:
	CONESIGHT_MEMLOCK=$${CONESIGHT_MEMLOCK:-$$(deploy/memlock.sh)} $(DEPLOY_COMPOSE) -p conesight up -d
	$(DEPLOY_COMPOSE) -p conesight ps

compose-down:
	$(DEPLOY_COMPOSE) -p conesight down -v

deploy-check:
	deploy/check.sh

## arm64 (Jetson) images from scratch: Debian's cross toolchain in a chroot, ONNX Runtime's
## aarch64 wheel, a debootstrapped trixie arm64 base (deploy/arm64/). Needs root; not in CI.
image-arm64: setup-runtime
	deploy/build-images.sh --arch arm64

## The arm64 `conesight` under qemu-user: --version and predict, cones compared with x86.
smoke-arm64:
	deploy/arm64/smoke.sh

## The paper's experiments on our pipeline (crates/conesight-eval + conesight_train.report):
## held-out synthetic frames (seeds 100-102) and real crops -> docs/results.md, docs/results.json,
## docs/results/*.png. Missing models are reported as not available. Deterministic (seeded).
EVAL_MODELS := --keypoint-model production=models/keypoints.onnx \
	--keypoint-model baseline=models/keypoints-baseline.onnx \
	--keypoint-model no_cross_ratio=models/keypoints-no-cr.onnx
# The keypoint evaluation also takes training checkpoints (first existing file wins).
REPORT_MODELS := --keypoint-model production=models/keypoints.onnx \
	--keypoint-model baseline=models/keypoints-baseline.onnx,build/train/keypoints-baseline/best.pt \
	--keypoint-model no_cross_ratio=models/keypoints-no-cr.onnx,build/train/keypoints-no-cr/best.pt
.PHONY: eval eval-check
# The real FSOCO splits, ranged by each cue (section 3b), when ../shared is there.
REAL_BOXES := $(if $(wildcard ../shared/data/real-train/fsoco-boxes/data.yaml),--real-boxes ../shared/data/real-train/fsoco-boxes,)

eval: setup
	@start=$$(date +%s); set -e; \
	cargo build --release -p conesight-eval; \
	cargo build --release -p conesight-sim --example sim; \
	rm -rf build/eval/cone-free; \
	./target/release/examples/sim --frames 100 --seed 103 --no-cones --format json \
	  --image-type jpg --quiet --out build/eval/cone-free; \
	./target/release/conesight-eval --out build/eval --patches-out build/eval/patches \
	  $(EVAL_MODELS) --detector models/detector.onnx $(REAL_BOXES); \
	PYTHONPATH=training $(PY) -m conesight_train.report --records build/eval --docs docs \
	  --synthetic-patches build/eval/patches $(REPORT_MODELS) \
	  --cone-free build/eval/cone-free --command "make eval" --started-at $$start; \
	echo "make eval: $$(( $$(date +%s) - start )) s"

## The cheap subset of `make eval` against the committed docs/results.json (CI runs it).
eval-check: setup
	cargo build --release -p conesight-eval
	$(PY) scripts/check_results.py --results docs/results.json --out build/eval-check
