#!/usr/bin/env bash
# svetlo's BVH against Embree on the same 1M-triangle mesh and the same rays.
# Installs embreex and numpy if missing, builds the Rust bench, runs both side by side.
# Extra arguments go to embree_compare.py (e.g. --repeat 9 --threads 1,2 --json out.json).
set -euo pipefail
cd "$(dirname "$0")/../.."
PY=${PYTHON:-python3}
if ! "$PY" -c "import numpy, embreex" 2>/dev/null; then
    "$PY" -m pip install --quiet numpy embreex
fi
CARGO_BUILD_JOBS=${CARGO_BUILD_JOBS:-1} cargo build --release -p svetlo --example raycast_bench
exec "$PY" bench/raycast/embree_compare.py "$@"
