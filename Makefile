# dqskin: `make demo` runs the main job, `make test` runs every test. Both set up .venv first.
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMPS := .stamps
RUST_SOURCES := $(shell find rust bench -name '*.rs' -o -name Cargo.toml) Cargo.toml pyproject.toml

.PHONY: setup build addon platforms test test-rust test-clippy test-python test-arm test-blenders demo bench clean

setup: $(STAMPS)/deps $(STAMPS)/module $(STAMPS)/addon

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMPS)/deps: requirements-dev.txt | $(PY)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements-dev.txt
	@mkdir -p $(STAMPS) && touch $@

# The extension module, built in release mode into .venv (editable: python/ is used in place).
$(STAMPS)/module: $(STAMPS)/deps $(RUST_SOURCES) python/dqskin/__init__.py
	VIRTUAL_ENV=$(abspath $(VENV)) $(VENV)/bin/maturin develop --release --quiet
	@mkdir -p $(STAMPS) && touch $@

# The Blender extension: the installable zip in dist/ (validated by Blender's own tool), then
# installed and enabled in the repo's Blender user folder, .blender_user/, which the Blender
# tests use through BLENDER_USER_RESOURCES, as users' scripts do.
# The module in it is linked through zig for manylinux2014 (glibc 2.17), so the zip loads on
# every Linux Blender runs on; addon/build.py refuses a module that needs a newer glibc.
ADDON_SOURCES := $(shell find addon -type f -not -path '*/__pycache__/*') $(wildcard python/dqskin/*.py python/dqskin/*.pyi)
$(STAMPS)/addon: $(STAMPS)/module $(ADDON_SOURCES)
	$(PY) addon/build_native.py linux-x64 --out target/wheels/linux-x64
	$(PY) addon/build.py target/wheels/linux-x64/dqskin-*.whl --out dist
	$(PY) addon/install.py dist/dq_skin-*-linux_x64.zip .blender_user
	@mkdir -p $(STAMPS) && touch $@

addon: $(STAMPS)/addon

# Zips for the platforms this machine can build but not run: Windows x64 and macOS (arm64,
# x86-64). Their binaries are checked (imports, linked libraries, minimum OS) but they have never
# been loaded in Blender, so they go to dist/unverified/ (see README, "Platforms").
OTHER_PLATFORMS := windows-x64 macos-arm64 macos-x64
platforms: setup
	for p in $(OTHER_PLATFORMS); do \
	  $(PY) addon/build_native.py $$p --out target/wheels/$$p && \
	  $(PY) addon/build.py target/wheels/$$p/dqskin-*.whl --out dist/unverified || exit 1; \
	done

build: setup

test: setup test-rust test-clippy test-python

# Property tests use a fixed seed here so that CI is deterministic; plain `cargo test` draws new
# random cases every run (and replays rust/core/proptest-regressions/ first).
test-rust:
	PROPTEST_RNG_SEED=20261122 cargo test --workspace --release

# Lints with warnings as errors, among them that every `unsafe` block says why it is sound
# (clippy::undocumented_unsafe_blocks, Cargo.toml); test-arm lints the aarch64 code too.
test-clippy:
	rustup component list --installed | grep -q '^clippy' || rustup component add clippy
	cargo clippy --workspace --release -- -D warnings

test-python: setup
	$(PY) -m pytest -q

# The core's tests on aarch64 (every kernel test runs the NEON copy there): cross-built for
# aarch64-unknown-linux-gnu, linked by zig from the pinned ziglang wheel (rust/cross/), run under
# qemu's user-mode emulation against Debian's aarch64 C library. Installs what is missing (the
# Rust target; qemu-user-static and libc6-arm64-cross through apt-get, as root on CI's fresh
# Debian). Measures nothing: ARM speed needs an ARM machine (README, Performance).
ARM_TARGET := aarch64-unknown-linux-gnu
ARM_SYSROOT := /usr/aarch64-linux-gnu
test-arm: $(STAMPS)/deps
	@if ! command -v qemu-aarch64-static >/dev/null || [ ! -e $(ARM_SYSROOT)/lib/ld-linux-aarch64.so.1 ]; then \
	  sudo=$$([ "$$(id -u)" = 0 ] || echo sudo); \
	  $$sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$sudo apt-get install -y -qq --no-install-recommends qemu-user-static libc6-arm64-cross; \
	fi
	rustup target list --installed | grep -qx $(ARM_TARGET) || rustup target add $(ARM_TARGET)
	rustup component list --installed | grep -q '^clippy' || rustup component add clippy
	cargo clippy -p dqskin-core --release --target $(ARM_TARGET) -- -D warnings
	DQSKIN_ZIG_PYTHON=$(abspath $(PY)) \
	CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=$(abspath rust/cross/aarch64-linux-gnu-cc) \
	CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="qemu-aarch64-static -L $(ARM_SYSROOT)" \
	PROPTEST_RNG_SEED=20261122 cargo test -p dqskin-core --release --target $(ARM_TARGET) --lib --tests

# The Blender tests on the other Blender releases, each from its own bpy wheel and CPython in
# .venvs/ (see tests/run_blenders.py); `make test` covers the pinned one.
test-blenders: setup
	$(PY) tests/run_blenders.py

demo: setup
	$(PY) -m dqskin.demo
	$(PY) addon/demo.py
	BLENDER_USER_RESOURCES=$(abspath .blender_user) $(PY) -m dqskin.blender compare --out out/rigs
	BLENDER_USER_RESOURCES=$(abspath .blender_user) $(PY) -m dqskin.blender compare ../shared/assets/CesiumMan.glb --out out/CesiumMan
	@cat out/rigs/report.md out/CesiumMan/report.md

# Kernel throughput against a memory-bandwidth reference, then DQ Skin against Blender's Armature
# modifier per frame in one Blender session (benchmarks, not tests).
bench: setup
	cargo run --release -p dqskin-bench -- --json target/bench-kernels.json
	$(PY) bench/blender_bench.py --out target/bench-blender.json

clean:
	rm -rf $(STAMPS) target $(VENV) .venvs
