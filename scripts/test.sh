#!/usr/bin/env bash
# Install everything the tests need on a fresh machine, lint, and run the test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh test
python3 -m ruff check .
python3 -m mypy
# test files spread over the cores (at most 4 workers: each trains with torch's own threads)
python3 -m pytest -q -m "not slow" -n auto --maxprocesses 4 --dist loadfile "$@"
