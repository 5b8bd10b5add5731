#!/usr/bin/env bash
# Installs what the comparison needs (Mitsuba 3.9.1, numpy, libLLVM 19 for the llvm variant), builds svetlo, runs it.
set -euo pipefail
cd "$(dirname "$0")/../.."
python3 -c "import mitsuba" 2>/dev/null || pip install -q mitsuba==3.9.1
python3 -c "import numpy" 2>/dev/null || pip install -q numpy
if ! ls /usr/lib/x86_64-linux-gnu/libLLVM-19.so* >/dev/null 2>&1; then
  (apt-get update -qq && apt-get install -y -qq libllvm19) || echo "libllvm19 not installed: the llvm_ad_rgb variant may fail"
fi
export DRJIT_LIBLLVM_PATH=${DRJIT_LIBLLVM_PATH:-$(ls /usr/lib/x86_64-linux-gnu/libLLVM-19.so* 2>/dev/null | head -n1)}
cargo build --release -q
python3 bench/mitsuba/cbox_compare.py "$@"
