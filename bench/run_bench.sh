#!/usr/bin/env bash
# End-to-end benchmark (by hand, not in CI): time per stage and peak RSS, median of RUNS runs,
#  1. the synthetic multi-scale scene of NOTES.md (igea at 1.6 m: 24 far 160x120 + 4 close 640x480
#     views, footprints 14.7 mm / 1.05 mm), mvs preset;
#  2. the ten real Stanford bunny scans, laser preset.
# Usage: bench/run_bench.sh [RUNS=3]   (needs build/bin/scalefuse and ../shared/data)
#   env EXTRA="--extract bricks" adds options to every fuse (e.g. to compare extraction paths).
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS="${1:-3}"
BIN="${BIN:-build/bin/scalefuse}"
DATA=../shared/data
WORK="${WORK:-/tmp/scalefuse-bench}"
mkdir -p "$WORK"
[ -d "$WORK/igea" ] || $BIN synth "$DATA/meshes/igea_triangles.ply" -o "$WORK/igea" --format colmap -q
run() {  # name input config
  for i in $(seq "$RUNS"); do
    rm -rf "$WORK/$1.ply.job"  # a finished job there would only be re-extracted
    $BIN fuse "$2" --config "configs/$3.toml" -o "$WORK/$1.ply" --stats "$WORK/$1.$i.json" -q ${EXTRA:-} >/dev/null
  done
  python3 - "$WORK" "$1" "$RUNS" <<'PY'
import json, statistics, sys
work, name, runs = sys.argv[1], sys.argv[2], int(sys.argv[3])
stats = [json.load(open(f"{work}/{name}.{i}.json")) for i in range(1, runs + 1)]
s0 = stats[0]
samples = s0["samples"]
print(f"{name}: {s0['depth_maps']} depth maps, {samples} samples, {s0['mesh']['triangles']} output triangles")
for stage in s0["seconds"]:
    print(f"  {stage:12s} {statistics.median(s['seconds'][stage] for s in stats):8.2f} s")
total = statistics.median(sum(s["seconds"].values()) for s in stats)
integ = statistics.median(s["seconds"]["integrate"] for s in stats)
print(f"  {'total':12s} {total:8.2f} s")
print(f"  integration  {samples / integ / 1e6:.3f} M samples/s")
print(f"  peak RSS     {statistics.median(s['peak_rss_bytes'] for s in stats) / 2**20:.0f} MiB")
print(f"  voxels       fused {sum(l['voxels_fused'] for l in s0['levels'])}, kept {sum(l['voxels_regularized'] for l in s0['levels'])}")
PY
}
run bunny "$DATA/stanford_bunny/scans" laser
run igea "$WORK/igea" mvs
