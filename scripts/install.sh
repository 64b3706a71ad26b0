#!/usr/bin/env bash
# Install the pipeline (and with "test", its test tools). torch is installed first at the pinned
# CPU build: any other torch requirement would pull several GB of CUDA packages.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -c "import torch" 2>/dev/null || python3 -m pip install -q "torch==2.13.0"
extra=""
[ "${1:-}" = "test" ] && extra="[test]"
python3 -m pip install -q -e ".${extra}"
