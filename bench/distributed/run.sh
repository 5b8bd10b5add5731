#!/usr/bin/env bash
# Distributed rendering on Dask: speed-up with 1 and 2 workers, overhead and bytes per task
# (--schemes: radiosity, photon, sppm and pssmlt by their own schemes).
# Needs the Python package installed (pip install ./crates/svetlo-py "dask[distributed]").
set -euo pipefail
cd "$(dirname "$0")/../.."
python3 bench/distributed/bench.py "$@"
