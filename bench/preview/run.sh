#!/usr/bin/env bash
# The cost of watching: the Cornell box at 512², rendered alternately without and with a
# connected page (bench/preview/client.py, which receives every update), one render thread.
# Prints the medians of wall time and of the process's CPU time (the preview's server threads
# included), their ratios, the update rate a page sees and the bytes per update.
#   bench/preview/run.sh [--runs 5] [--spp 16] [--threads 1]
set -euo pipefail
cd "$(dirname "$0")/../.."
RUNS=5 SPP=16 THREADS=1
while [ $# -gt 0 ]; do
  case "$1" in
    --runs) RUNS=$2; shift 2 ;;
    --spp) SPP=$2; shift 2 ;;
    --threads) THREADS=$2; shift 2 ;;
    *) echo "unknown option $1" >&2; exit 2 ;;
  esac
done
cargo build --release -q -p svetlo-cli
BIN=target/release/svetlo
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
python3 - "$BIN" "$RUNS" "$SPP" "$THREADS" "$OUT" <<'PY'
import json, os, re, statistics, subprocess, sys, time
bin_, runs, spp, threads, out = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4], sys.argv[5]
base = [bin_, "render", "scenes/cornell-box.xml", "--width", "512", "--height", "512", "--spp", spp,
        "--threads", threads, "-o", os.path.join(out, "b.exr")]

def finish(p):
    # svetlo's own CPU time (all its threads), not the client's.
    _, status, r = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    assert p.returncode == 0, f"svetlo exited with {p.returncode}"
    return r.ru_utime + r.ru_stime

def plain():
    t0 = time.monotonic()
    p = subprocess.Popen(base, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    c = finish(p)
    return time.monotonic() - t0, c

def watched():
    t0 = time.monotonic()
    p = subprocess.Popen(base + ["--preview"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    for line in p.stderr:
        m = re.match(r"preview: (\S+)", line)
        if m:
            break
    client = subprocess.Popen([sys.executable, "bench/preview/client.py", m.group(1)], stdout=subprocess.PIPE, text=True)
    p.stderr.read()
    c = finish(p)
    wall = time.monotonic() - t0
    stats = json.loads(client.communicate()[0])
    return wall, c, stats, client

rows = {"plain": [], "watched": []}
pages = []
for i in range(runs):
    rows["plain"].append(plain())
    w, c, stats, _ = watched()
    rows["watched"].append((w, c))
    pages.append(stats)
med = {k: (statistics.median(r[0] for r in v), statistics.median(r[1] for r in v)) for k, v in rows.items()}
print(f"cornell-box 512x512, {spp} spp, {threads} render thread(s), {runs} alternating runs each")
for k in ("plain", "watched"):
    print(f"  {k:8s} wall median {med[k][0]:.2f} s   CPU median {med[k][1]:.2f} s (svetlo, all threads)")
print(f"  ratio watched/plain: wall {med['watched'][0] / med['plain'][0]:.3f}, CPU {med['watched'][1] / med['plain'][1]:.3f}")
fps = statistics.median(p["frames_per_s"] for p in pages)
print(f"  page: {statistics.median(p['frames'] for p in pages):.0f} images per render, {fps:.2f} images/s, "
      f"{pages[0]['bytes_per_frame']} bytes per image, {pages[0]['bytes_per_status']:.0f} bytes per status")
PY
