#!/usr/bin/env bash
# Equal-time relMSE of path, bdpt, pssmlt and mlt on scenes/door.xml, scenes/caustic.xml and
# scenes/indirect-room.xml, with the Metropolis acceptance rates. Needs only svetlo (its
# `compare` computes relMSE) and python3.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --release -q
python3 bench/mlt/compare.py "$@"
