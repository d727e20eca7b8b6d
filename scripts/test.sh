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
# one pytest worker per core (pytest-xdist): the robot and doctor tests are long and mostly one-threaded; a
# worker takes the next test when it is free, so the long ones do not queue behind each other
python3 -m pytest -q -n auto --dist worksteal tests
