#!/usr/bin/env bash
# Radiosity methods on the Cornell box at ~1k, 4k, 16k and 64k elements (element sizes 0.5,
# 0.25, 0.125, 0.0625): time and memory to a 1 % residual, form factors or links, progressive
# rows for a displayable image, relMSE against Tungsten. Prints a Markdown table.
# Extra arguments go to the example (e.g. --sizes 0.5,0.25 --max-matrix 5000 --epsilon 0.02).
set -euo pipefail
cd "$(dirname "$0")/../.."
CARGO_BUILD_JOBS=${CARGO_BUILD_JOBS:-1} cargo build --release -p svetlo --example radiosity_bench
exec ./target/release/examples/radiosity_bench --scene ../shared/scenes/bitterli/cornell-box "$@"
