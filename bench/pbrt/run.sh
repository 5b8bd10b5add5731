#!/usr/bin/env bash
# Parse speed of the pbrt-v4 reader (issue #15): a scene with an N-triangle `trianglemesh`
# written inline as text, and the same mesh as a binary PLY (`plymesh`). Times `svetlo info`
# (the whole load: parse, mesh checks, accelerator build) on one thread, median of RUNS, and
# prints MB/s of the text file over the load and over the load minus the PLY scene's (what the
# text costs beyond the same mesh read in binary, i.e. the tokenizer and number parsing).
# Usage: bench/pbrt/run.sh [triangles, default 1000000]
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=target/release/svetlo
N=${1:-1000000}; RUNS=${RUNS:-3}
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
python3 - "$N" "$tmp" <<'PY'
import math, random, struct, sys
n, d = int(sys.argv[1]), sys.argv[2]
side = int(math.ceil(math.sqrt(n / 2))) + 1
random.seed(1)
pts = [(x / side, y / side, 0.01 * random.random()) for y in range(side) for x in range(side)]
tris = []
for y in range(side - 1):
    for x in range(side - 1):
        i = y * side + x
        tris += [(i, i + 1, i + side), (i + 1, i + side + 1, i + side)]
tris = tris[:n]
head = 'LookAt 0.5 0.5 2  0.5 0.5 0  0 1 0\nCamera "perspective" "float fov" 45\nFilm "rgb" "integer xresolution" 64 "integer yresolution" 64\nWorldBegin\nLightSource "point" "point3 from" [0.5 0.5 1] "rgb I" [1 1 1]\n'
with open(f"{d}/text.pbrt", "w") as f:
    f.write(head + 'Shape "trianglemesh"\n  "point3 P" [\n')
    for p in pts:
        f.write("%.6f %.6f %.6f\n" % p)
    f.write(']\n  "integer indices" [\n')
    for t in tris:
        f.write("%d %d %d\n" % t)
    f.write("]\n")
with open(f"{d}/mesh.ply", "wb") as f:
    f.write(b"ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\nelement face %d\nproperty list uchar int vertex_indices\nend_header\n" % (len(pts), len(tris)))
    f.write(b"".join(struct.pack("<fff", *p) for p in pts))
    f.write(b"".join(struct.pack("<Biii", 3, *t) for t in tris))
with open(f"{d}/ply.pbrt", "w") as f:
    f.write(head + 'Shape "plymesh" "string filename" "mesh.ply"\n')
PY
cpu() { /usr/bin/time -f "%U %S" -o "$tmp/t" "$@" >/dev/null 2>&1; awk '{print $1+$2}' "$tmp/t"; }
median() { printf '%s\n' "$@" | sort -n | sed -n "$(( ($#+1)/2 ))p"; }
text=(); ply=()
for i in $(seq "$RUNS"); do
  text+=("$(RAYON_NUM_THREADS=1 cpu $BIN info "$tmp/text.pbrt")")
  ply+=("$(RAYON_NUM_THREADS=1 cpu $BIN info "$tmp/ply.pbrt")")
done
mb=$(awk -v b="$(stat -c %s "$tmp/text.pbrt")" 'BEGIN{printf "%.1f", b/1e6}')
plymb=$(awk -v b="$(stat -c %s "$tmp/mesh.ply")" 'BEGIN{printf "%.1f", b/1e6}')
t=$(median "${text[@]}"); p=$(median "${ply[@]}")
echo "$N triangles: text scene $mb MB, load CPU ${text[*]} s (median $t); PLY $plymb MB, load CPU ${ply[*]} s (median $p)"
awk -v mb="$mb" -v t="$t" -v p="$p" 'BEGIN{printf "text: %.1f MB/s over the whole load, %.1f MB/s over the load minus the PLY scene'"'"'s\n", mb/t, (t>p)? mb/(t-p) : 0}'
