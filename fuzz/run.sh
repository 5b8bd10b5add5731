#!/bin/sh
# Run every fuzz target for SECONDS each (default 60), one after the other, at low priority
# (the machine is shared), and print the executions each reached. Needs the nightly
# toolchain and cargo-fuzz (`cargo install cargo-fuzz`). Crashes land in fuzz/artifacts/;
# copy each reproducer into crates/svetlo/tests/data/fuzz/<target>/ once it is fixed, so that
# the stable test `fuzz_replay` keeps it fixed.
set -eu
secs=${1:-60}
cd "$(dirname "$0")"
targets="mitsuba_xml obj ply image integrator_options photometry lpe"
nice -n 15 cargo +nightly fuzz build --release 2>&1 | tail -n 3
for t in $targets; do
    mkdir -p "corpus/$t" "artifacts/$t" "work/$t"
    # New inputs go to work/ (not committed); corpus/ is the small seed set.
    log="work/$t.log"
    nice -n 15 cargo +nightly fuzz run --release "$t" "work/$t" "corpus/$t" -- \
        -dict=dict/scene.dict -max_total_time="$secs" -max_len=16384 -rss_limit_mb=2048 -timeout=10 \
        -print_final_stats=1 >"$log" 2>&1 || echo "$t: stopped (crash or error), see $log and artifacts/$t"
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo "?")
    echo "$t: $execs executions in ${secs} s"
done
