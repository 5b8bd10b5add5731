#!/usr/bin/env bash
# The classic pipeline's speed (issue 5): Z-buffer frames per second on the Cornell box and
# on a generated 1M-triangle mesh at 512x512 on one thread, and ms per spp of whitted and
# distributed against path. Options pass through to the example (see its header), e.g.
#   bench/classic/run.sh --frames 50 --ss 2
# With --callgrind, also counts the instructions of one Cornell-box frame (valgrind), which
# unlike wall time does not depend on what else the machine runs (512x512, ss 1).
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --release --example classic_bench
bin=target/release/examples/classic_bench
if [[ "${1:-}" == "--callgrind" ]]; then
    shift
    out=$(mktemp -d)
    trap 'rm -rf "$out"' EXIT
    # One prepare and 1 vs 3 frames: the difference is two frames' instructions.
    for n in 1 3; do
        valgrind --tool=callgrind --callgrind-out-file="$out/cg.$n" "$bin" --frames $n --skip mesh,mc >/dev/null 2>"$out/log.$n"
    done
    a=$(grep -o 'refs: *[0-9,]*' "$out/log.1" | tr -dc 0-9)
    b=$(grep -o 'refs: *[0-9,]*' "$out/log.3" | tr -dc 0-9)
    echo "{\"bench\": \"zbuffer-callgrind\", \"scene\": \"cornell-box\", \"instructions_per_frame\": $(( (b - a) / 2 ))}"
fi
"$bin" "$@"
