#!/usr/bin/env bash
# A whole fuse (every stage) of two binaries compared on one input, runs alternating (A B A B ...),
# so that the ratios hold on a noisy machine. Per binary: the medians of wall time, peak RSS and
# each stage's seconds (from --stats), then B/A of each, and whether every run wrote the same mesh
# (sha256 of the PLY). For changes outside integration (allocation, extraction), where
# integrate_ab.sh sees only the first stages.
# Usage: bench/fuse_ab.sh INPUT CONFIG RUNS BIN_A BIN_B [fuse args...]
#   e.g. bench/fuse_ab.sh ../shared/data/stanford_bunny/scans configs/laser.toml 5 old/scalefuse build/bin/scalefuse
set -euo pipefail
[ $# -ge 5 ] || { sed -n 2,8p "$0" >&2; exit 2; }
INPUT=$1 CONFIG=$2 RUNS=$3 A=$4 B=$5
shift 5
WORK=$(mktemp -d /tmp/scalefuse-fuse-ab.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
for i in $(seq "$RUNS"); do
  for side in A B; do
    bin=$A
    [ $side = B ] && bin=$B
    rm -rf "$WORK/job"
    /usr/bin/time -f "%e %M" -o "$WORK/time" "$bin" fuse "$INPUT" --config "$CONFIG" -o "$WORK/m.ply" \
      --job "$WORK/job" --stats "$WORK/stats.json" -q "$@" > /dev/null
    mesh=$(sha256sum "$WORK/m.ply" | cut -c1-16)
    python3 - "$WORK" "$side" "$mesh" >> "$WORK/runs" <<'PY'
import json, sys
work, side, mesh = sys.argv[1:4]
wall, rss = open(f"{work}/time").read().split()[-2:]
s = json.load(open(f"{work}/stats.json"))["seconds"]
print(json.dumps({"side": side, "mesh": mesh, "wall": float(wall), "peak RSS MiB": float(rss) / 1024, **s}))
PY
  done
done
python3 - "$WORK/runs" "$A" "$B" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
names = {"A": sys.argv[2], "B": sys.argv[3]}
keys = [k for k in rows[0] if k not in ("side", "mesh")]
med = {}
for side in "AB":
    r = [x for x in rows if x["side"] == side]
    med[side] = {k: statistics.median(x.get(k, 0) for x in r) for k in keys}
    print(f"{side} ({names[side]}), median of {len(r)}: " + ", ".join(f"{k} {v:.2f}" for k, v in med[side].items()))
print("B / A: " + ", ".join(f"{k} {med['B'][k] / med['A'][k]:.3f}" for k in keys if med["A"][k]))
meshes = {x["mesh"] for x in rows}
print("meshes identical across all runs" if len(meshes) == 1 else f"meshes DIFFER: {sorted(meshes)}")
PY
