# dqskin: `make demo` runs the main job, `make test` runs every test. Both set up .venv first.
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
# Windows venvs keep their programs in Scripts/ (the hosted runners of .github/workflows/).
VENV_BIN := $(VENV)/$(if $(filter Windows_NT,$(OS)),Scripts,bin)
PY := $(VENV_BIN)/python
# The platform whose wheel and zip `make setup` builds and the Blender tests install: this
# machine's (`make platforms` builds the others from Linux).
PLATFORM ?= linux-x64
STAMPS := .stamps
RUST_SOURCES := $(shell find rust bench -name '*.rs' -o -name Cargo.toml) Cargo.toml pyproject.toml

.PHONY: setup build addon platforms repo test test-format test-rust test-clippy test-python test-blender test-blenders test-windows test-arm demo bench clean

setup: $(STAMPS)/deps $(STAMPS)/module $(STAMPS)/addon

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMPS)/deps: requirements-dev.txt | $(PY)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements-dev.txt
	@mkdir -p $(STAMPS) && touch $@

# The extension module, built in release mode into .venv (editable: python/ is used in place).
$(STAMPS)/module: $(STAMPS)/deps $(RUST_SOURCES) python/dqskin/__init__.py
	VIRTUAL_ENV=$(abspath $(VENV)) $(VENV_BIN)/maturin develop --release --quiet
	@mkdir -p $(STAMPS) && touch $@

# The Blender extension: the compiled core as the wheel a release uploads to PyPI (linked through
# zig for manylinux2014, glibc 2.17, so it loads on every Linux Blender runs on; addon/build.py
# refuses a module that needs a newer glibc) in dist/, and the installable zip Blender's own
# builder makes around it (validated by Blender's own tool); then the zip is installed and
# enabled in the repo's Blender user folder, .blender_user/, which the Blender tests use through
# BLENDER_USER_RESOURCES, as users' scripts do. dist/ is also an extension repository: its
# index.json (addon/repository.py) lists the zips built so far (`make repo` builds them all).
ADDON_SOURCES := $(shell find addon -type f -not -path '*/__pycache__/*') $(wildcard python/dqskin/*.py python/dqskin/*.pyi)
$(STAMPS)/addon: $(STAMPS)/module $(ADDON_SOURCES)
	$(PY) addon/build_native.py $(PLATFORM) --out target/wheels/$(PLATFORM)
	$(PY) addon/build.py target/wheels/$(PLATFORM)/dqskin-*.whl --out dist
	$(PY) addon/repository.py dist
	$(PY) addon/install.py dist/dq_skin-*-$(subst -,_,$(PLATFORM)).zip .blender_user
	@mkdir -p $(STAMPS) && touch $@

addon: $(STAMPS)/addon

# The wheels and zips of the platforms this machine builds but cannot load in Blender: Windows
# x64 and macOS (arm64, x86-64), beside the Linux ones in dist/. Their binaries are checked
# (imports, exports, linked libraries, minimum OS); the Windows core's tests run under Wine
# (test-windows); hosted runners run everything natively (.github/workflows/platforms.yml).
OTHER_PLATFORMS := windows-x64 macos-arm64 macos-x64
platforms: setup
	for p in $(OTHER_PLATFORMS); do $(PY) addon/build_native.py $$p --out target/wheels/$$p || exit 1; done
	$(PY) addon/build.py $(foreach p,linux-x64 $(OTHER_PLATFORMS),target/wheels/$(p)/dqskin-*.whl) --out dist
	$(PY) addon/repository.py dist

# The extension repository users add in Blender (Get Extensions > Repositories > Add Remote
# Repository, the address of dist/index.json) to install DQ Skin and get its updates: every
# platform's zip in dist/ and the index Blender's own `extension server-generate` writes for them.
repo: platforms

build: setup

test: setup test-format test-rust test-clippy test-python test-blender

# Formatting and lints first (the quickest to fail): rustfmt (rustfmt.toml) over the Rust code, and
# ruff's lint and formatter (pyproject.toml) over every Python file.
test-format: $(STAMPS)/deps
	rustup component list --installed | grep -q '^rustfmt' || rustup component add rustfmt
	cargo fmt --check
	$(VENV_BIN)/ruff check
	$(VENV_BIN)/ruff format --check

# Property tests use a fixed seed here so that CI is deterministic; plain `cargo test` draws new
# random cases every run (and replays rust/core/proptest-regressions/ first).
test-rust:
	PROPTEST_RNG_SEED=20261122 cargo test --workspace --release
	cargo run --release -q -p dqskin-bench -- --help >/dev/null  # make bench's first command starts

# Lints with warnings as errors, among them that every `unsafe` block says why it is sound
# (clippy::undocumented_unsafe_blocks, Cargo.toml); test-arm lints the aarch64 code too.
test-clippy:
	rustup component list --installed | grep -q '^clippy' || rustup component add clippy
	cargo clippy --workspace --release -- -D warnings

# The module's tests (on the editable module of .venv), then the Blender tests on the module of
# the installed extension zip (tests/blender/conftest.py): a pytest process per test file, two at
# a time (DQSKIN_TEST_JOBS), as tests/run_blenders.py runs the other releases.
test-python: setup
	$(PY) -m pytest -q tests/python

test-blender: setup
	$(PY) tests/run_blenders.py --pinned

# The Rust core's tests (every SIMD copy the CPU has, the thread pool, the centers precompute)
# built for Windows (x86_64-pc-windows-gnu, linked by zig as the Windows module is) and run under
# Wine: Debian's wine64, installed here if missing (as root, as CI runs).
WINE = $(or $(shell command -v wine64),/usr/lib/wine/wine64)
$(STAMPS)/wine:
	command -v wine64 >/dev/null || test -x /usr/lib/wine/wine64 || \
	  (apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends wine64)
	@mkdir -p $(STAMPS) && touch $@

# Wine 8 has no bcryptprimitives.dll, from which Rust's standard library takes random bytes on
# Windows 10+ (which all ship it): the prefix gets a small one that forwards to bcrypt.dll.
WINE_ENV = WINEPREFIX=$(abspath target/wine) WINEDEBUG=-all WINEDLLOVERRIDES="mscoree,mshtml="
WINE_PRNG := target/wine/drive_c/windows/system32/bcryptprimitives.dll
$(WINE_PRNG): tests/wine/bcryptprimitives.c $(STAMPS)/wine $(STAMPS)/deps
	$(WINE_ENV) $(WINE) wineboot --init
	$(PY) -m ziglang cc -target x86_64-windows-gnu -shared -O2 -o $@ $< -lbcrypt

test-windows: $(STAMPS)/deps $(STAMPS)/wine $(WINE_PRNG)
	rustup target list --installed | grep -qx x86_64-pc-windows-gnu || rustup target add x86_64-pc-windows-gnu
	PATH=$(abspath addon/zig):$$PATH DQSKIN_ZIG_PYTHON=$(abspath $(PY)) \
	CARGO_TARGET_X86_64_PC_WINDOWS_GNU_LINKER=$(abspath addon/zig/windows-gnu-cc) \
	CARGO_TARGET_X86_64_PC_WINDOWS_GNU_RUNNER=$(WINE) \
	$(WINE_ENV) PROPTEST_RNG_SEED=20261122 nice -n 10 cargo test -p dqskin-core --release --target x86_64-pc-windows-gnu

# The core's tests on aarch64 (every kernel test runs the NEON copy there): cross-built for
# aarch64-unknown-linux-gnu, linked by zig from the pinned ziglang wheel (rust/cross/), run under
# qemu's user-mode emulation against Debian's aarch64 C library. Installs what is missing (the
# Rust target; qemu-user-static and libc6-arm64-cross through apt-get, as root on CI's fresh
# Debian). Measures nothing: ARM speed needs an ARM machine (docs/performance.md).
ARM_TARGET := aarch64-unknown-linux-gnu
ARM_SYSROOT := /usr/aarch64-linux-gnu
# The naive O(vertices × triangles) reference on the 3,000-vertex creature (twice) takes minutes under
# emulation; the precompute's NEON sums are checked against it on the twist cylinder and on
# random meshes there, and the creature's certified fast path still runs. The stroke update on
# the creature (a full precompute twice) likewise, and the weights (voxels and solvers, no
# per-ISA code: they run natively and under Wine) take minutes there too.
ARM_SKIP := precompute_matches_the_naive_formula_on_the_creature after_a_stroke_the_update_equals_the_full_precompute strokes_that_follow_one_another weights::
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
	PROPTEST_RNG_SEED=20261122 cargo test -p dqskin-core --release --target $(ARM_TARGET) --lib --tests -- $(foreach t,$(ARM_SKIP),--skip $(t))

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
# On a CPU with AVX-512 the kernels also run as the AVX2 copy, which most artists' CPUs run.
bench: setup
	cargo run --release -p dqskin-bench -- --json target/bench-kernels.json
	if grep -qw avx512f /proc/cpuinfo 2>/dev/null; then \
	  DQSKIN_SIMD=avx2 cargo run --release -p dqskin-bench -- --json target/bench-kernels-avx2.json; fi
	$(PY) bench/blender_bench.py --out target/bench-blender.json
	$(PY) bench/report.py > target/bench-report.md  # the tables of docs/performance.md

clean:
	rm -rf $(STAMPS) target $(VENV) .venvs
