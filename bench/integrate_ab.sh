#!/usr/bin/env bash
# Integration of two binaries compared on one input, runs alternating (A B A B ...), so that the
# ratios hold on a noisy machine. Each run is a fresh `fuse --integrate-only` job; per binary it
# prints the medians of wall time, the bounds / plan / integrate stages (from --stats), minor page
# faults and peak RSS, and whether the two binaries' fields are identical (bench/field_hash.py:
# sha256 of each brick's decompressed payload, so tile formats 4 and 5 compare; the generation
# numbers in tile names follow the plan's order and are left out).
# With CORE=N in the environment every run is pinned to core N (taskset), and the fastest run of
# each binary is printed too: one core's runs close together drift less than the two cores
# of bench/pair_ab.sh differ on some machines (bench/README.md, session 32).
# Usage: [CORE=N] bench/integrate_ab.sh INPUT CONFIG RUNS BIN_A BIN_B [fuse args...]
#   e.g. bench/integrate_ab.sh ../shared/data/7scenes_50frames configs/rgbd.toml 3 old/scalefuse build/bin/scalefuse --memory-limit 1.5G
#        CORE=1 bench/integrate_ab.sh /work/q/igea configs/mvs.toml 6 old/scalefuse build/bin/scalefuse --threads 1
set -euo pipefail
[ $# -ge 5 ] || { sed -n 2,12p "$0" >&2; exit 2; }
PIN=()
[ -n "${CORE:-}" ] && PIN=(taskset -c "$CORE")
INPUT=$1 CONFIG=$2 RUNS=$3 A=$4 B=$5
shift 5
WORK=$(mktemp -d /tmp/scalefuse-ab.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
for i in $(seq "$RUNS"); do
  for side in A B; do
    bin=$A
    [ $side = B ] && bin=$B
    rm -rf "$WORK/job"
    "${PIN[@]}" /usr/bin/time -f "%e %R %M" -o "$WORK/time" "$bin" fuse "$INPUT" --config "$CONFIG" -o "$WORK/m.ply" \
      --job "$WORK/job" --integrate-only --stats "$WORK/stats.json" -q "$@" > /dev/null
    tiles=$("$(dirname "$0")/field_hash.py" "$WORK/job/tiles")
    python3 - "$WORK" "$side" "$tiles" >> "$WORK/runs" <<'PY'
import json, sys
work, side, tiles = sys.argv[1:4]
wall, faults, rss = open(f"{work}/time").read().split()[-3:]
s = json.load(open(f"{work}/stats.json"))["seconds"]
print(side, wall, s.get("bounds", 0), s.get("plan", 0), s["integrate"], faults, rss, tiles)
PY
  done
done
python3 - "$WORK/runs" "$A" "$B" <<'PY'
import statistics, sys
rows = [l.split() for l in open(sys.argv[1])]
names = {"A": sys.argv[2], "B": sys.argv[3]}
med = {}
for side in "AB":
    r = [x for x in rows if x[0] == side]
    m = [statistics.median(float(x[k]) for x in r) for k in range(1, 7)]
    med[side] = m
    print(f"{side} ({names[side]}), median of {len(r)}: wall {m[0]:.2f} s, bounds {m[1]:.2f} s, plan {m[2]:.2f} s, "
          f"integrate {m[3]:.3f} s (fastest {min(float(x[4]) for x in r):.3f} s), {m[4]:.0f} minor faults, "
          f"peak RSS {m[5] / 1024:.0f} MiB")
print("B / A: wall {:.3f}, plan {:.3f}, integrate {:.3f}".format(
    *(med["B"][k] / med["A"][k] if med["A"][k] else float("nan") for k in (0, 2, 3))))
hashes = {x[7] for x in rows}
print("fields identical across all runs" if len(hashes) == 1 else f"fields DIFFER: {sorted(hashes)}")
PY
