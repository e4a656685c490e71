# dqskin: `make demo` runs the main job, `make test` runs every test. Both set up .venv first.
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMPS := .stamps
RUST_SOURCES := $(shell find rust bench -name '*.rs' -o -name Cargo.toml) Cargo.toml pyproject.toml

.PHONY: setup build test test-rust test-python demo bench clean

setup: $(STAMPS)/deps $(STAMPS)/module

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMPS)/deps: requirements-dev.txt | $(PY)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements-dev.txt
	@mkdir -p $(STAMPS) && touch $@

# The extension module, built in release mode into .venv (editable: python/ is used in place).
$(STAMPS)/module: $(STAMPS)/deps $(RUST_SOURCES) python/dqskin/__init__.py
	VIRTUAL_ENV=$(abspath $(VENV)) $(VENV)/bin/maturin develop --release --quiet
	@mkdir -p $(STAMPS) && touch $@

build: setup

test: setup test-rust test-python

# Property tests use a fixed seed here so that CI is deterministic; plain `cargo test` draws new
# random cases every run (and replays rust/core/proptest-regressions/ first).
test-rust:
	PROPTEST_RNG_SEED=20261122 cargo test --workspace --release

test-python: setup
	$(PY) -m pytest -q

demo: setup
	$(PY) -m dqskin.demo

# Kernel throughput against a memory-bandwidth reference (a benchmark, not a test).
bench:
	cargo run --release -p dqskin-bench -- --json target/bench-kernels.json

clean:
	rm -rf $(STAMPS) target $(VENV)
