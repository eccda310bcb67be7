#!/usr/bin/env bash
# The checks that read the code without running it: Rust formatting, clippy, rustdoc's
# links, that the fuzz targets compile, and ruff on every Python file. scripts/test.sh
# runs what checks behaviour; .ci/run runs both, the tests first.
# Installs what it needs from crates.io and PyPI. Run from anywhere.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/steps.sh   # CARGO_INCREMENTAL on CI, `step`, `target`
# Check mode compiles the dependencies as metadata only, which a test build cannot
# reuse: a directory of its own keeps the two from invalidating each other.
export CARGO_TARGET_DIR="$target/check"

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy --workspace --all-targets -- -D warnings"
# rust-version = 1.88 in Cargo.toml: clippy's incompatible_msrv refuses a std API newer.
cargo clippy --workspace --all-targets --locked -- -D warnings

step "rustdoc: broken or private intra-doc links"
# The C library's crate is named `qtvpr` too (libqtvpr.so), so its docs would overwrite
# the core's: include/qtvpr.h documents it.
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --exclude qtvpr-capi --no-deps --locked

step "the fuzz targets compile"
# fuzz/ is not a workspace member (libFuzzer needs a sanitizer build to run); stable can
# check that its targets compile. Its own lockfile, and its own target directory.
unset CARGO_TARGET_DIR
cargo check --manifest-path fuzz/Cargo.toml --locked

step "ruff"
venv="$target/lint-venv"
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
# The pin of the `lint` extra (pyproject.toml), without building the package.
ruff=$(sed -n 's/^lint = .*"\(ruff[^"]*\)".*/\1/p' pyproject.toml)
[ -n "$ruff" ] || { echo "no ruff pin in pyproject.toml's lint extra" >&2; exit 1; }
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check "$ruff"
"$venv/bin/ruff" check py tests benches scripts
