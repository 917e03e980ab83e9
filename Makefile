# conesight: the two commands a fresh machine needs are `make demo` and `make test`.
# Both run scripts/setup.sh first (idempotent, cached in build/): ONNX Runtime library from the
# onnxruntime==1.31.1 wheel, a Python venv with the tools, Debian packages if missing.

SHELL := /bin/bash
ROOT := $(CURDIR)
PY := $(ROOT)/build/venv/bin/python
export ORT_DYLIB_PATH ?= $(ROOT)/build/onnxruntime/libonnxruntime.so.1.31.1

.PHONY: setup demo test test-rust test-python lint bench bench-pnp clean

setup:
	@bash scripts/setup.sh

## The main job on the embedded defaults.
demo: setup
	cargo build --release -p conesight-cli
	./target/release/conesight demo

## Every test: Rust (unit, property, integration) and Python.
test: setup
	cargo test --workspace
	$(MAKE) --no-print-directory test-python

test-python: setup
	@status=0; $(PY) -m pytest -q training bench || status=$$?; \
	  if [ $$status -eq 5 ]; then echo "pytest: no Python tests collected"; status=0; fi; exit $$status

lint: setup
	cargo fmt --all -- --check
	cargo clippy --workspace --all-targets -- -D warnings
	$(PY) -m ruff check training bench scripts
	$(PY) -m ruff format --check training bench scripts

## Criterion benchmarks (hot paths).
bench:
	cargo bench --workspace

## Our cone PnP against OpenCV's solvePnP variants on the same 10,000 correspondences.
bench-pnp: setup
	cargo build --release -p conesight-core --example pnp_bench
	$(PY) bench/pnp_vs_opencv.py --bench-bin target/release/examples/pnp_bench

clean:
	rm -rf build target
