#!/usr/bin/env bash
# Install the pipeline on a fresh machine and run the main job: every stage on a synthetic session.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
pipeline demo --quick --out "${1:-out/demo}"
