#!/usr/bin/env bash
# Extraction alone, binaries compared in one run (by hand, not in CI): each run copies an
# integrated job (`scalefuse fuse ... --integrate-only --extract bricks --job JOB`) and resumes it,
# so regularization and extraction run from the same field; the binaries alternate run by run, so
# the noise of this machine hits them alike. Prints the stats' extract and regularize seconds, CPU
# and wall seconds, and the median extract seconds per binary.
# Usage: bench/extract_resume.sh JOB RUNS BIN [BIN...]
set -euo pipefail
JOB="$1"; RUNS="$2"; shift 2
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT
for i in $(seq "$RUNS"); do
  for bin in "$@"; do
    rm -rf "$WORK/job"; cp -a "$JOB" "$WORK/job"
    /usr/bin/time -f "%U %S %e" -o "$WORK/time" "$bin" resume "$WORK/job" -q --stats "$WORK/stats.json" >/dev/null
    python3 - "$bin" "$WORK" <<'PY' | tee -a "$WORK/lines"
import json, sys
bin, work = sys.argv[1], sys.argv[2]
s = json.load(open(f"{work}/stats.json"))
u, sy, wall = (float(x) for x in open(f"{work}/time").read().split())
e = s["extract"]
print(f"{bin}\textract {s['seconds']['extract']:.2f}\tregularize {s['seconds'].get('regularize', 0):.2f}"
      f"\tcpu {u + sy:.1f}\twall {wall:.1f}\twindow points {e['window_points']}\tin cubes {e.get('window_voxels_in_cubes', 0)}")
PY
  done
done
python3 - "$WORK/lines" <<'PY'
import statistics, sys
runs = {}
for line in open(sys.argv[1]):
    f = line.split("\t")
    runs.setdefault(f[0], []).append(float(f[1].split()[1]))
for bin, t in runs.items():
    print(f"median extract {statistics.median(t):7.2f} s  {bin} ({len(t)} runs)")
PY
