#!/usr/bin/env bash
# Equal-time relMSE of svetlo's path, light and bdpt (and Mitsuba 3's path) on the project's
# caustic and indirect-room scenes. Installs Mitsuba 3.9.1 and numpy if missing, builds svetlo.
set -euo pipefail
cd "$(dirname "$0")/../.."
python3 -c "import mitsuba" 2>/dev/null || pip install -q mitsuba==3.9.1
python3 -c "import numpy" 2>/dev/null || pip install -q numpy
cargo build --release -q
python3 bench/bidir/compare.py "$@"
