#!/usr/bin/env bash
# Citywall-scale benchmark (issue 3; by hand, not in CI). Renders the synthetic city block of
# engine/synth/city.h once (564 depth maps of 500x375: 64 far, 20 facade, 480 street views of 24
# statues, footprints 137 mm far / 5 mm on the statues), then fuses it with the mvs preset:
#   1. integration with --memory-limit LIMIT (default 1.5G), under /usr/bin/time -v;
#   2. the same integration with no practical limit (64G), in another job;
#   3. compares the two integrated fields brick by brick (final checkpoint tiles, byte for byte);
#   4. unless SKIP_EXTRACT=1, regularization and extraction of the limited job (scalefuse resume).
# Prints wall time, peak RSS, spill traffic, tile bytes and voxels per level.
# Usage: bench/city/run_city.sh   (env: WORK=/tmp/scalefuse-bench LIMIT=1.5G THREADS=2 SKIP_EXTRACT=0 BIN=build/bin/scalefuse)
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN="${BIN:-$PWD/build/bin/scalefuse}"
DATA=../shared/data
WORK="${WORK:-/tmp/scalefuse-bench}"
LIMIT="${LIMIT:-1.5G}"
THREADS="${THREADS:-2}"
mkdir -p "$WORK"
if [ ! -f "$WORK/city/synth.json" ]; then
  rm -rf "$WORK/city"
  /usr/bin/time -f "synth: %e s, peak RSS %M KiB" \
    "$BIN" synth --city "$DATA/meshes/igea_triangles.ply" "$DATA/stanford_bunny/reconstruction/bun_zipper.ply" \
    -o "$WORK/city" --colmap-binary
fi
fuse() {  # name limit extra...
  local name=$1 limit=$2
  shift 2
  rm -rf "$WORK/$name.job" "$WORK/$name.ply"
  /usr/bin/time -v -o "$WORK/$name.time" "$BIN" fuse "$WORK/city" -o "$WORK/$name.ply" --job "$WORK/$name.job" \
    --config configs/mvs.toml --threads "$THREADS" --memory-limit "$limit" --stats "$WORK/$name.json" -q "$@" > "$WORK/$name.log" 2>&1
  python3 - "$WORK" "$name" <<'PY'
import re, sys, json
work, name = sys.argv[1], sys.argv[2]
t = open(f"{work}/{name}.time").read()
wall = re.search(r"Elapsed \(wall clock\) time.*: (.*)", t).group(1)
rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", t).group(1))
s = json.load(open(f"{work}/{name}.json"))
sp = s["spill"]
print(f"{name}: wall {wall}, peak RSS {rss / 1024:.0f} MiB; {s['depth_maps']} depth maps, {s['samples']} samples")
print(f"  integrate {s['seconds']['integrate']:.1f} s = {s['samples'] / s['seconds']['integrate'] / 1e6:.3f} M samples/s"
      f"; peak RSS at its end {s['peak_rss_integrate_bytes'] / 2**20:.0f} MiB")
print(f"  plan: {s['tiles']} tiles, {s['sweep_steps']} steps, {s['frame_reads']} depth-map reads; "
      f"field estimated {s['plan_estimate_bytes'] / 2**30:.2f} GiB, measured {s['field_bytes'] / 2**30:.2f} GiB")
print(f"  spilled {sp['bricks_spilled']} / reloaded {sp['bricks_reloaded']} bricks, "
      f"{sp['bytes_written'] / 2**30:.2f} GiB written / {sp['bytes_read'] / 2**30:.2f} GiB read")
for l in s["levels"]:
    print(f"  level {l['level']:2d} cell {l['cell_size'] * 1000:9.2f} mm  triangles {l['triangles']:11d}")
PY
}
echo "== integration, --memory-limit $LIMIT"
fuse city_limited "$LIMIT" --integrate-only
"$BIN" status "$WORK/city_limited.job"
echo "== integration, --memory-limit 64G"
fuse city_unlimited 64G --integrate-only
"$BIN" status "$WORK/city_unlimited.job"
echo "== the two integrated fields, brick by brick"
python3 - "$WORK/city_limited.job/tiles" "$WORK/city_unlimited.job/tiles" <<'PY'
import os, sys, hashlib
def bricks(d):
    out = {}
    for f in os.listdir(d):
        if f.endswith(".tile"):
            brick = f.split(".")[0]
            out[brick] = hashlib.sha256(open(os.path.join(d, f), "rb").read()).hexdigest()
    return out
a, b = bricks(sys.argv[1]), bricks(sys.argv[2])
same = sum(1 for k in a if b.get(k) == a[k])
print(f"bricks: {len(a)} limited, {len(b)} unlimited, {same} byte-identical")
sys.exit(0 if same == len(a) == len(b) else 1)
PY
if [ "${SKIP_EXTRACT:-0}" != 1 ]; then
  echo "== regularization and extraction (resume of the limited job)"
  /usr/bin/time -v -o "$WORK/city_extract.time" "$BIN" resume "$WORK/city_limited.job" --threads "$THREADS" \
    --memory-limit "$LIMIT" --stats "$WORK/city_extract.json" > "$WORK/city_extract.log" 2>&1 || echo "extraction failed: see $WORK/city_extract.log"
  grep -E "Elapsed|Maximum resident" "$WORK/city_extract.time"
  tail -25 "$WORK/city_extract.log"
fi
