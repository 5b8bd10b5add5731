#!/usr/bin/env bash
# Equal-time relMSE of the photon methods (sppm, photon) against path tracing on the two
# scenes where tracing from the lights should win: scenes/caustic.xml (a glass sphere's
# caustic from a small light) and scenes/indirect-room.xml (light from the next room).
#
# The reference of each scene is a long path-traced render (unbiased; REF_TIME seconds, kept
# in $OUT and reused). Its own noise adds the same floor to every method's relMSE, so the
# ratios printed are lower bounds on the true advantage. Timing is wall clock: run on an
# otherwise idle machine, or compare ratios from one run.
#
# Usage: bench/photon/run.sh            (env: TIME=30 REF_TIME=1200 RES=64 SEEDS="1 2" OUT=target/bench-photon)
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=${SVETLO:-target/release/svetlo}
TIME=${TIME:-30}
REF_TIME=${REF_TIME:-1200}
RES=${RES:-64}
SEEDS=${SEEDS:-"1 2"}
OUT=${OUT:-target/bench-photon}
SCENES=${SCENES:-scenes}
INTEGRATORS=${INTEGRATORS:-"path sppm photon"}
mkdir -p "$OUT"
[ -x "$BIN" ] || cargo build --release

# Scene parameters for a RES-wide image (indirect-room is 4:3).
defs() {
    case $1 in
        caustic) echo "-Dres=$RES" ;;
        indirect-room) echo "-Dresx=$RES -Dresy=$((RES * 3 / 4))" ;;
    esac
}

relmse() { "$BIN" compare "$1" "$2" | awk '/^relMSE/ {print $2}'; }

printf '| scene | integrator | time (s) | spp/iterations | relMSE (per seed) | mean relMSE | path / this |\n'
printf '|---|---|---|---|---|---|---|\n'
for scene in caustic indirect-room; do
    xml="$SCENES/$scene.xml"
    ref="$OUT/$scene-ref-$RES.exr"
    if [ ! -f "$ref" ]; then
        # shellcheck disable=SC2046
        "$BIN" render "$xml" $(defs $scene) --integrator path --time "$REF_TIME" --seed 987654 -o "$ref" >"$OUT/$scene-ref.log" 2>&1
    fi
    path_mean=""
    for integ in $INTEGRATORS; do
        errs=""; spps=""
        for seed in $SEEDS; do
            img="$OUT/$scene-${integ%%:*}-$seed.exr"
            # shellcheck disable=SC2046
            "$BIN" render "$xml" $(defs $scene) --integrator "$integ" --time "$TIME" --seed "$seed" -o "$img" >"$OUT/$scene-${integ%%:*}-$seed.log" 2>&1
            spps="$spps $(awk '/^spp/ {print $2}' "$OUT/$scene-${integ%%:*}-$seed.log")"
            errs="$errs $(relmse "$img" "$ref")"
        done
        mean=$(echo "$errs" | awk '{s = 0; for (i = 1; i <= NF; i++) s += $i; printf "%.3e", s / NF}')
        [ "$integ" = path ] && path_mean=$mean
        ratio=$(awk -v a="${path_mean:-0}" -v b="$mean" 'BEGIN {if (a > 0 && b > 0) printf "%.1f", a / b; else print "-"}')
        printf '| %s | %s | %s | %s | %s | %s | %s |\n' "$scene" "$integ" "$TIME" "${spps# }" "${errs# }" "$mean" "$ratio"
    done
done
