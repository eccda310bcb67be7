#!/usr/bin/env bash
# Every check of the project, from a fresh clone: Rust format, lints and tests, then the
# wheel built into a virtualenv, its stubs checked, the Python code linted, and the
# Python tests (wheel, reference and CLI).
# Installs what it needs from crates.io and PyPI. Run from anywhere.
#
# One build of the workspace serves everything: `cargo test` builds the CLI binary
# (dev profile: the project's crates at opt-level 1, dependencies at 2) that the Python
# tests run, and the C library and the wheel are built with the same profile and, through
# crates/workspace-hack, the same features into the same target directory, so they
# compile only their own crates (and pyo3). CONTRIBUTING.md says how long each step takes.
set -euo pipefail
cd "$(dirname "$0")/.."
# A fresh clone builds everything once: incremental compilation's caches would only
# cost time there (and disk). A developer's repeated local runs keep them.
[ -z "${CI:-}" ] || export CARGO_INCREMENTAL=0

# Each step says how long the one before it took (CONTRIBUTING.md quotes these).
step_name="" step_start=$SECONDS
step() {
    [ -z "$step_name" ] || printf '== %s: %d s\n' "$step_name" $((SECONDS - step_start))
    step_name="$*" step_start=$SECONDS
    printf '\n== %s\n' "$*"
}
checks=""
finish() {
    [ -z "$step_name" ] || printf "== %s: %d s (total %d s)\n" "$step_name" $((SECONDS - step_start)) $SECONDS
    # A failure before the background checks were waited for ends them too.
    if [ -n "$checks" ] && kill -0 "$checks" 2> /dev/null; then
        pkill -P "$checks" 2> /dev/null || true
        kill "$checks" 2> /dev/null || true
    fi
}
trap finish EXIT
target=$(cargo metadata --format-version 1 --no-deps --locked | python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')

step "cargo fmt --check"
cargo fmt --all -- --check

# The checks that only type-check (clippy, rustdoc, the fuzz targets) run beside the
# build and the tests, in a target directory of their own (cargo locks one per build):
# they compile the dependencies in check mode, which the tests' build cannot reuse, and
# on 2 cores they fill what the build leaves idle. Their output is printed when they
# are waited for, below.
mkdir -p "$target"
check_log="$target/checks.log"
(
    set -euo pipefail
    export CARGO_TARGET_DIR="$target/check"
    start=$SECONDS
    cargo clippy --workspace --all-targets --locked -- -D warnings
    echo "== cargo clippy --workspace --all-targets -- -D warnings: $((SECONDS - start)) s" && start=$SECONDS
    # Broken or private intra-doc links fail. The C library's crate is named `qtvpr` too
    # (libqtvpr.so), so its docs would overwrite the core's: include/qtvpr.h documents it.
    RUSTDOCFLAGS="-D warnings" cargo doc --workspace --exclude qtvpr-capi --no-deps --locked
    echo "== rustdoc: $((SECONDS - start)) s" && start=$SECONDS
    # fuzz/ is not a workspace member (libFuzzer needs a sanitizer build to run); stable
    # can check that its targets compile. Its own target directory, fuzz/target.
    unset CARGO_TARGET_DIR
    cargo check --manifest-path fuzz/Cargo.toml --locked
    echo "== fuzz targets compile: $((SECONDS - start)) s"
) > "$check_log" 2>&1 &
checks=$!

step "no AES, bzip2, zstd or LZMA crate in the build"
# Semantics §12: an .npz holds stored or deflated members, and its zip layer (rawzip,
# which decompresses nothing, and flate2's deflate) compiles no other codec.
banned=$(cargo tree --workspace --locked -e normal,build --prefix none | sed 's/ .*//' | sort -u |
    grep -xiE 'zip|aes|bzip2|bzip2-sys|libbz2-rs-sys|zstd|zstd-sys|zstd-safe|lzma-rs|lzma-sys|liblzma|xz2|deflate64|pbkdf2|hmac|sha1|constant_time_eq' || true)
if [ -n "$banned" ]; then
    echo "crates the zip layer must not bring: $banned" >&2
    exit 1
fi
step "cargo test"
# The zip layer's fixed fuzzing budget (the fuzz target npz_archive's function, without
# libFuzzer): 3000 structured mutations of each of ~45 valid and hostile archives, in
# the test npy::archive::tests::the_zip_layer_survives_a_fixed_fuzzing_budget (300 when
# cargo test runs alone).
export QTVPR_FUZZ_ITERATIONS=3000
# The tests on the real data of ../shared/data are #[ignore]d (cargo test reports them
# as such without it): they run when it is there.
if [ -d ../shared/data ]; then
    cargo test --workspace --locked -- --include-ignored
else
    echo "../shared/data is absent: the tests that need it are reported ignored"
    cargo test --workspace --locked
fi
step "the C library and the CLI alone compile nothing cargo test did not"
# A dependency compiled again would mean other features in that build than in the
# tests': crates/workspace-hack is stale (`cargo hakari generate`), and the C checks
# and the wheel would each compile most of the tree again.
again=$(cargo build --locked -p qtvpr-capi -p qtvpr-cli 2>&1 | sed -n 's/^ *Compiling \([^ ]*\) .*/\1/p' | grep -vx 'qtvpr-capi' || true)
if [ -n "$again" ]; then
    echo "compiled again with other features: $again; regenerate crates/workspace-hack (cargo hakari generate)" >&2
    exit 1
fi
step "the README's Rust example, from the repository root"
# Built by cargo test above (the workspace's features include npy), run as a reader would.
"$target/debug/examples/readme"
step "C interface"
scripts/capi.sh   # the C interface: C/C++ examples (shared, static) against the CLI, error paths, valgrind

step "clippy, rustdoc and the fuzz targets' check (started beside the build)"
status=0
wait "$checks" || status=$?
checks=""
if [ "$status" != 0 ]; then
    cat "$check_log"
    echo "clippy, rustdoc or the fuzz targets' check failed: its output is above" >&2
    exit 1
fi
# Their warnings and timings; not the hundreds of "Checking" lines.
grep -vE '^ *(Checking|Compiling|Documenting|Finished|Generated|Locking|Adding|Downloaded|Downloading) ' "$check_log" || true

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

step "stubtest and ruff"
# The stubs against the installed compiled module (from the repository root, where
# `qtvpr` is not importable from source), then the lint of every Python file.
"$venv/bin/python" -m mypy.stubtest --mypy-config-file pyproject.toml qtvpr._native
"$venv/bin/ruff" check py tests benches scripts

step "pytest"
# Run from tests/ so that the installed wheel, not the source tree, is imported.
cd tests
# Then the Python examples of README.md and docs/*.md (Sybil, ../conftest.py); -rs prints
# why each skipped test was skipped (most: ../shared/data is absent). On every core
# (pytest-xdist), a file to a worker: a document's examples run in order, in one
# namespace, and a module's fixtures (the Dask cluster) start once.
QTVPR_CLI="$target/debug/qtvpr-cli" "$venv/bin/python" -m pytest -q -rs -p no:cacheprovider -n auto --dist loadfile \
    . ../README.md ../docs
