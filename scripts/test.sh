#!/usr/bin/env bash
# Every check of behaviour, from a fresh clone: the Rust tests, the C interface, then the
# wheel built into a virtualenv, its stubs checked against it, and the Python tests
# (wheel, reference, CLI, the documents' examples). scripts/lint.sh reads the code
# (formatting, clippy, rustdoc, the fuzz targets' check, ruff); .ci/run runs both.
# Installs what it needs from crates.io, PyPI and apt (valgrind, as root). Run from anywhere.
#
# One build of the workspace serves everything: the Rust tests build the CLI binary
# (dev profile: the project's crates at opt-level 1, dependencies at 2) that the Python
# tests run, and the C library and the wheel are built with the same profile and, through
# crates/workspace-hack, the same features into the same target directory, so they
# compile only their own crates (and pyo3). CONTRIBUTING.md says how long each step takes.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/steps.sh   # CARGO_INCREMENTAL on CI, `step`, `target`

step "set-up: valgrind for the C checks (apt, as root)"
# scripts/capi.sh runs the C examples under valgrind; without it (not root, no apt) it
# says so and skips that part alone.
if command -v valgrind > /dev/null; then
    valgrind --version
elif [ "$(id -u)" = 0 ] && command -v apt-get > /dev/null; then
    apt-get update -qq && apt-get install -y -qq valgrind > /dev/null && valgrind --version
else
    echo "valgrind is missing and cannot be installed here (not root, or no apt-get): scripts/capi.sh will skip its valgrind step"
fi

step "no AES, bzip2, zstd or LZMA crate in the build"
# Semantics §12: an .npz holds stored or deflated members, and its zip layer (rawzip,
# which decompresses nothing, and flate2's deflate) compiles no other codec.
banned=$(cargo tree --workspace --locked -e normal,build --prefix none | sed 's/ .*//' | sort -u |
    grep -xiE 'zip|aes|bzip2|bzip2-sys|libbz2-rs-sys|zstd|zstd-sys|zstd-safe|lzma-rs|lzma-sys|liblzma|xz2|deflate64|pbkdf2|hmac|sha1|constant_time_eq' || true)
if [ -n "$banned" ]; then
    echo "crates the zip layer must not bring: $banned" >&2
    exit 1
fi
step "cargo nextest run (cargo test without cargo-nextest), then the doc tests"
# The zip layer's fixed fuzzing budget (the fuzz target npz_archive's function, without
# libFuzzer): 3000 structured mutations of each of ~45 valid and hostile archives, in
# the test npy::archive::tests::the_zip_layer_survives_a_fixed_fuzzing_budget (300 when
# cargo test runs alone).
export QTVPR_FUZZ_ITERATIONS=3000
# The tests on the real data of ../shared/data are #[ignore]d (reported as such without
# it): they run when it is there.
[ -d ../shared/data ] || echo "../shared/data is absent: the tests that need it are reported ignored"
# cargo-nextest runs every test binary's tests side by side, each in its own process
# (cargo test runs the binaries one after another); it runs no doc tests, cargo test
# --doc does. Without it, cargo test runs everything.
if cargo nextest --version > /dev/null 2>&1; then
    ignored=(); [ ! -d ../shared/data ] || ignored=(--run-ignored all)
    cargo nextest run --workspace --locked --no-fail-fast "${ignored[@]}"
    cargo test --workspace --locked --doc
else
    echo "cargo-nextest is not installed (cargo install --locked cargo-nextest): cargo test runs the tests"
    ignored=(); [ ! -d ../shared/data ] || ignored=(-- --include-ignored)
    cargo test --workspace --locked "${ignored[@]}"
fi
step "the C library and the CLI alone compile nothing the tests did not"
# A dependency compiled again would mean other features in that build than in the
# tests': crates/workspace-hack is stale (`cargo hakari generate`), and the C checks
# and the wheel would each compile most of the tree again.
# Read from cargo's JSON messages: one compiler-artifact per unit, `fresh` when nothing
# was compiled. No artifact at all means the check could not see the build, and fails.
cargo build --locked -p qtvpr-capi -p qtvpr-cli --message-format json-render-diagnostics > "$target/rebuild.json"
python3 - "$target/rebuild.json" <<'PY'
import json, sys
from pathlib import Path

units = [m for m in map(json.loads, open(sys.argv[1])) if m.get("reason") == "compiler-artifact"]
if not units:
    sys.exit("the rebuild check read no compiler-artifact message from cargo: it cannot tell what was compiled")
# A unit named by its manifest's folder and its target (the C library's target is named
# qtvpr too); the C library's own crate is the one compiled.
again = {f"{Path(u['manifest_path']).parent.name} ({u['target']['name']})" for u in units if not u["fresh"]}
again = sorted(again - {"qtvpr-capi (qtvpr)"})
if again:
    sys.exit(f"compiled again with other features: {', '.join(again)}; regenerate crates/workspace-hack (cargo hakari generate)")
print(f"{len(units)} units, none compiled again but the C library's own")
PY
step "the README's Rust example, from the repository root"
# Built by the tests above (the workspace's features include npy), run as a reader would.
"$target/debug/examples/readme"
step "C interface"
scripts/capi.sh   # the C interface: C/C++ examples (shared, static) against the CLI, error paths, valgrind

step "wheel into a virtualenv"
venv="$target/test-venv"
# A venv is kept between local runs (a fresh clone has none); the wheel is always rebuilt.
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check "maturin>=1.9,<2"
rm -rf "$target/test-wheels"
"$venv/bin/maturin" build --quiet --locked --profile dev --interpreter "$venv/bin/python" --out "$target/test-wheels"
wheel=$(ls "$target"/test-wheels/qtvpr-*.whl)
pip=("$venv/bin/python" -m pip install --quiet --disable-pip-version-check)
"${pip[@]}" "$wheel[test,lint,dask]"              # the test, lint and Dask (qtvpr.dask) dependencies
"${pip[@]}" --force-reinstall --no-deps "$wheel"   # this build, even if the version is unchanged
# qtvpr.ros's ROS 2 Jazzy packages have wheels for CPython 3.11 only; elsewhere
# tests/test_ros.py skips and says why (pytest -rs).
if "$venv/bin/python" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
    "${pip[@]}" "$wheel[ros]"
    "${pip[@]}" ./ros/qtvpr_msgs   # the interface package: ROS 2's generators run in pip's build (ros/qtvpr_msgs)
else
    echo "not CPython 3.11: no ROS 2 Jazzy wheels, tests/test_ros.py will skip"
fi

step "stubtest"
# The stubs against the installed compiled module (from the repository root, where
# `qtvpr` is not importable from source).
"$venv/bin/python" -m mypy.stubtest --mypy-config-file pyproject.toml qtvpr._native

step "pytest"
# Run from tests/ so that the installed wheel, not the source tree, is imported.
cd tests
# Then the Python examples of README.md and docs/*.md (Sybil, ../conftest.py); -rs prints
# why each skipped test was skipped (most: ../shared/data is absent). On every core
# (pytest-xdist), a file to a worker: a document's examples run in order, in one
# namespace, and a module's fixtures (the Dask cluster) start once.
QTVPR_CLI="$target/debug/qtvpr-cli" "$venv/bin/python" -m pytest -q -rs -p no:cacheprovider -n auto --dist loadfile \
    . ../README.md ../docs
