#!/usr/bin/env bash
# Runs every test of didim: formatting, clippy (warnings are errors), the Rust tests, and pytest
# against the installed package. Installs what it needs first (Python packages and the package itself).
set -euo pipefail
cd "$(dirname "$0")/.."

python3 -m pip install --quiet --upgrade pip >/dev/null 2>&1 || true
python3 -m pip install --quiet "maturin>=1.7,<2"
python3 -m pip install --quiet -e ".[test]"

cargo fmt --all -- --check
cargo clippy --workspace --all-targets -- -D warnings
cargo test --workspace --all-targets
python3 -m mypy.stubtest didim._core
python3 -m pytest -q tests
