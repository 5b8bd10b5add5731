#!/usr/bin/env bash
# Overhead of AOVs against none at equal spp, one thread, alternating runs; prints per method
# the ratio of the median CPU times (user+sys) with and without AOVs, the per-pair ratios
# with their median, and the ratio of the minima (noise on a shared machine only adds time). Usage: bench/lpe/run.sh [scene.xml] [spp] [res]
# METHODS='a b' picks the methods (default: path, which is the eight-wide kernel where the scene
# qualifies, the scalar path tracer, bdpt and mlt); RUNS the alternating runs; PRESET=lecture renders the
# lecture preset's five AOVs instead of the eight below; MEASURE=instructions counts
# instructions under valgrind (callgrind) instead of CPU time: deterministic, so one run
# each is enough on a loaded machine (use a small res and spp: valgrind is ~50x slower).
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=${BIN:-target/release/svetlo}
SCENE=${1:-scenes/caustic.xml}; SPP=${2:-16}; RES=${3:-64}; RUNS=${RUNS:-5}
if [ "${PRESET:-}" = lecture ]; then
  AOVS=(--aov-preset lecture)
else
  AOVS=(--aov a='C [LB]' --aov b='C D [LB]' --aov c='C D [^LB]+ [LB]' --aov d='C [GS] .* [LB]'
        --aov e='C D S+ L' --aov f='C <R.> L' --aov g='C . .+ L' --aov h='L D* E')
fi
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
cpu() {
  if [ "${MEASURE:-cpu}" = instructions ]; then
    valgrind --tool=callgrind --callgrind-out-file="$tmp/cg" "$@" >/dev/null 2>"$tmp/v"
    awk '/^summary:/{print $2}' "$tmp/cg"
  else
    /usr/bin/time -f "%U %S" -o "$tmp/t" "$@" >/dev/null 2>&1; awk '{print $1+$2}' "$tmp/t"
  fi
}
median() { printf '%s\n' "$@" | sort -g | awk '{v[NR]=$1} END{print (NR%2) ? v[(NR+1)/2] : (v[NR/2]+v[NR/2+1])/2}'; }
minimum() { printf '%s\n' "$@" | sort -g | head -1; }
for m in ${METHODS:-path "path:simd=false" bdpt "mlt:bootstrap=20000"}; do
  ratios=(); bases=(); withs=()
  for i in $(seq "$RUNS"); do
    base=$(cpu $BIN render "$SCENE" -Dres=$RES --spp $SPP --threads 1 --integrator "$m" -o "$tmp/n.exr")
    with=$(cpu $BIN render "$SCENE" -Dres=$RES --spp $SPP --threads 1 --integrator "$m" "${AOVS[@]}" -o "$tmp/a.exr")
    bases+=("$base"); withs+=("$with")
    ratios+=("$(awk -v a="$with" -v b="$base" 'BEGIN{printf "%.3f", a/b}')")
  done
  mb=$(median "${bases[@]}"); mw=$(median "${withs[@]}"); nb=$(minimum "${bases[@]}"); nw=$(minimum "${withs[@]}")
  echo "$m: ${PRESET:-8} AOVs / none, ${MEASURE:-cpu}: medians $mw / $mb = $(awk -v a="$mw" -v b="$mb" 'BEGIN{printf "%.3f", a/b}'); pair ratios ${ratios[*]} (median $(median "${ratios[@]}")); minima $nw / $nb = $(awk -v a="$nw" -v b="$nb" 'BEGIN{printf "%.3f", a/b}')"
done
