#!/usr/bin/env bash
# Integration of two binaries compared side by side: each pair runs A and B at the same time, one
# per core (`taskset`, --threads 1), and the next pair swaps the cores. A noisy neighbour or a slow
# core then slows both or each in turn, so the geometric mean of two pairs' ratios (cores swapped)
# cancels it. On this machine runs one after the other drift by 10-40 % between minutes, and one
# core was at times 25-30 % slower than the other for minutes on end; two copies of one binary
# gave swapped-pair means within 1.5 % of 1. Use 6 pairs or more and read the median.
# Prints per pair the integrate seconds (from --stats) and ratio B/A, then the median over pairs
# of the swapped-pair geometric means, and whether the binaries' fields are identical
# (bench/field_hash.py; the generation numbers in tile names are left out).
# Usage: bench/pair_ab.sh INPUT CONFIG PAIRS BIN_A BIN_B [fuse args...]   (PAIRS even)
#   e.g. bench/pair_ab.sh /work/q/igea configs/mvs.toml 6 old/scalefuse build/bin/scalefuse
set -euo pipefail
[ $# -ge 5 ] || { sed -n 2,12p "$0" >&2; exit 2; }
INPUT=$1 CONFIG=$2 PAIRS=$3 A=$4 B=$5
shift 5
EXTRA=("$@")
[ "$(nproc)" -ge 2 ] || { echo "pair_ab.sh: needs two cores" >&2; exit 2; }
WORK=$(mktemp -d /tmp/scalefuse-pair.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
one() {  # binary core side
  rm -rf "$WORK/$3"
  taskset -c "$2" "$1" fuse "$INPUT" --config "$CONFIG" -o "$WORK/$3.ply" --job "$WORK/$3" --integrate-only \
    --threads 1 --stats "$WORK/$3.json" -q "${EXTRA[@]}" > /dev/null
}
for i in $(seq "$PAIRS"); do
  if [ $((i % 2)) = 1 ]; then ca=0 cb=1; else ca=1 cb=0; fi
  one "$A" $ca a &
  pa=$!
  one "$B" $cb b &
  pb=$!
  wait $pa
  wait $pb
  ta=$("$(dirname "$0")/field_hash.py" "$WORK/a/tiles")
  tb=$("$(dirname "$0")/field_hash.py" "$WORK/b/tiles")
  python3 - "$WORK" "$ca" "$ta" "$tb" >> "$WORK/pairs" <<'PY'
import json, sys
work, core_a, ta, tb = sys.argv[1:5]
a = json.load(open(f"{work}/a.json"))["seconds"]["integrate"]
b = json.load(open(f"{work}/b.json"))["seconds"]["integrate"]
print(core_a, a, b, b / a, "identical" if ta == tb else "different")
PY
  tail -1 "$WORK/pairs" | awk '{printf "pair (A on core %s): A %.3f s, B %.3f s, B/A %.3f, tiles %s\n", $1, $2, $3, $4, $5}'
done
python3 - "$WORK/pairs" "$A" "$B" <<'PY'
import math, statistics, sys
rows = [l.split() for l in open(sys.argv[1])]
ratios = [float(r[3]) for r in rows]
swapped = [math.sqrt(ratios[i] * ratios[i + 1]) for i in range(0, len(ratios) - 1, 2)]
print(f"A = {sys.argv[2]}, B = {sys.argv[3]}")
print(f"integrate B/A: median of {len(swapped)} swapped-pair means {statistics.median(swapped):.3f} "
      f"(pairs {min(ratios):.3f}-{max(ratios):.3f}); median A {statistics.median(float(r[1]) for r in rows):.3f} s, "
      f"B {statistics.median(float(r[2]) for r in rows):.3f} s; tiles "
      + ("identical" if all(r[4] == "identical" for r in rows) else "DIFFERENT"))
PY
