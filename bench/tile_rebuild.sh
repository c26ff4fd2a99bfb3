#!/usr/bin/env bash
# Rebuilding damaged checkpoint tiles (issue 6; by hand, not in CI). Integrates INPUT once into a
# job (--integrate-only), then, RUNS times each, on a fresh copy of that job:
#   none     resumes it untouched (the cost of opening the job and finding nothing to do);
#   smallest / median / largest   deletes that one tile (by bytes) and resumes: the tile is rebuilt
#            by re-integrating every depth map of the job into its brick alone;
#   K largest  deletes the K largest tiles (K=4 by default), and all deletes every tile: all damaged
#            tiles are found at once and rebuilt in one pass over the depth maps.
# Prints per case the depth maps read (those whose recorded reach meets the lost bricks), the median wall time of the resume and of the rebuilds as the program reports
# them, against the wall time of the job's whole integration (a ratio measured in one run).
# Usage: bench/tile_rebuild.sh INPUT RUNS [fuse args...]
#   e.g. bench/tile_rebuild.sh ../shared/data/stanford_bunny/scans 5 --config configs/laser.toml
# env: BIN=build/bin/scalefuse WORK=/tmp/scalefuse-rebuild-bench K=4
set -euo pipefail
cd "$(dirname "$0")/.."
INPUT="$(realpath "$1")"; RUNS="$2"; shift 2
BIN="${BIN:-$PWD/build/bin/scalefuse}"
WORK="${WORK:-/tmp/scalefuse-rebuild-bench}"
K="${K:-4}"
rm -rf "$WORK"; mkdir -p "$WORK"
start=$(date +%s.%N)
"$BIN" fuse "$INPUT" -o "$WORK/mesh.ply" --job "$WORK/job" --integrate-only -q "$@" >/dev/null
full=$(echo "$(date +%s.%N) - $start" | bc)
# Tiles of the last checkpoint, smallest first (name = brick coordinates and generation).
mapfile -t tiles < <(find "$WORK/job/tiles" -name '*.tile' -printf '%s %p\n' | sort -n | cut -d' ' -f2)
n=${#tiles[@]}
[ "$n" -gt 0 ] || { echo "no tiles in $WORK/job/tiles" >&2; exit 1; }
depth_maps=$("$BIN" status "$WORK/job" --json | python3 -c 'import json,sys; print(json.load(sys.stdin)["integrated"])')
printf 'input %s: %s depth maps, %d tiles, integration %.2f s\n' "$INPUT" "$depth_maps" "$n" "$full"
declare -A victims=(
  [none]=""
  [smallest]="${tiles[0]}"
  [median]="${tiles[$((n / 2))]}"
  [largest]="${tiles[$((n - 1))]}"
  [${K}_largest]="${tiles[*]: -$K}"
  [all]="${tiles[*]}"
)
for run in $(seq "$RUNS"); do
  for case in none smallest median largest "${K}_largest" all; do
    rm -rf "$WORK/copy"; cp -a "$WORK/job" "$WORK/copy"
    for t in ${victims[$case]}; do rm "$WORK/copy/tiles/$(basename "$t")"; done
    : > "$WORK/stderr"
    start=$(date +%s.%N)
    "$BIN" fuse "$INPUT" -o "$WORK/mesh.ply" --job "$WORK/copy" --integrate-only -q "$@" 2>"$WORK/stderr" >/dev/null
    wall=$(echo "$(date +%s.%N) - $start" | bc)
    # "...; rebuilt it by re-integrating the K of the job's N depth maps that reach it (S s)", once per tile
    rebuilt=$(grep -c 'rebuilt it' "$WORK/stderr" || true)
    expected=$(echo ${victims[$case]} | wc -w)
    [ "$rebuilt" = "$expected" ] || { echo "$case: $rebuilt rebuilds reported, $expected expected:" >&2; cat "$WORK/stderr" >&2; exit 1; }
    # every line of one resume reports the time of all its rebuilds together
    seconds=$(grep -o 'that reach it ([0-9.]* s' "$WORK/stderr" | head -1 | grep -o '[0-9.]*' || true)
    reading=$(grep -o "re-integrating the [0-9]* of the job" "$WORK/stderr" | head -1 | grep -o '[0-9]*' || echo 0)
    kib=0; for t in ${victims[$case]}; do kib=$((kib + $(stat -c %s "$t") / 1024)); done
    printf '%s\t%s\t%s\t%s\t%s\t%s\n' "$case" "$wall" "${seconds:-0}" "$expected" "$kib" "${reading:-0}" >> "$WORK/lines"
  done
done
python3 - "$WORK/lines" "$full" "$RUNS" <<'PY'
import statistics, sys
lines, full, runs = sys.argv[1], float(sys.argv[2]), sys.argv[3]
cases = {}
for line in open(lines):
    case, wall, seconds, count, kib, reading = line.split("\t")
    cases.setdefault(case, []).append((float(wall), float(seconds), int(count), int(kib), int(reading)))
print(f"median of {runs} runs          tiles  tile KiB  maps read  resume wall  rebuild (reported)  rebuild / integration")
for case, rows in cases.items():
    wall = statistics.median(r[0] for r in rows)
    rebuild = statistics.median(r[1] for r in rows)
    print(f"{case:28s} {rows[0][2]:5d} {rows[0][3]:9d} {rows[0][4]:10d} {wall:10.2f} s {rebuild:16.2f} s {rebuild / full:19.3f}")
PY
