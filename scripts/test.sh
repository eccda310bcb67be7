#!/usr/bin/env bash
# Every check of the project, from a fresh clone: Rust format, lints and tests, then the
# wheel built into a fresh virtualenv, its stubs checked, the Python code linted, and the
# Python tests (wheel, reference and CLI).
# Installs what it needs from crates.io and PyPI. Run from anywhere.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n== %s\n' "$*"; }

step "cargo fmt --check"
cargo fmt --all -- --check
step "cargo clippy"
cargo clippy --workspace --all-targets --locked -- -D warnings
step "cargo test"
cargo test --workspace --locked
step "cargo build --release (qtvpr-cli)"
cargo build --release --locked -p qtvpr-cli

step "wheel into a fresh virtualenv"
venv=target/test-venv
rm -rf "$venv"
python3 -m venv "$venv"
"$venv/bin/python" -m pip install --quiet --upgrade pip
"$venv/bin/python" -m pip install --quiet ".[test,lint]"

step "stubtest and ruff"
# The stubs against the installed compiled module (from the repository root, where
# `qtvpr` is not importable from source), then the lint of every Python file.
"$venv/bin/python" -m mypy.stubtest --mypy-config-file pyproject.toml qtvpr._native
"$venv/bin/ruff" check py tests benches

step "pytest"
# Run from tests/ so that the installed wheel, not the source tree, is imported.
cd tests
QTVPR_CLI="$PWD/../target/release/qtvpr-cli" "../$venv/bin/python" -m pytest -q -p no:cacheprovider .
