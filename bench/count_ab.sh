#!/usr/bin/env bash
# Integration of two binaries counted rather than timed: each runs `fuse --integrate-only
# --threads 1` under valgrind's cachegrind (instructions, conditional branches, and branches its
# simple predictor mispredicts), both at once, one per core. The counts do not drift with the
# machine as times do here (bench/README.md), so a change of 1 % shows; they are not times:
# cache misses and the real predictor are left out. Needs valgrind (apt-get install valgrind);
# a run takes ~30x the integration's time.
# Prints per binary the counts, which cover the whole process (bounds, plan and integrate alike),
# B/A per count, and whether the two fields are identical (bench/field_hash.py: each brick's
# decompressed payload, whatever the tile format; generation numbers left out).
# Usage: bench/count_ab.sh INPUT CONFIG BIN_A BIN_B [fuse args...]
#   e.g. bench/count_ab.sh /work/q/igea configs/mvs.toml old/scalefuse build/bin/scalefuse
set -euo pipefail
[ $# -ge 4 ] || { sed -n 2,12p "$0" >&2; exit 2; }
INPUT=$1 CONFIG=$2 A=$3 B=$4
shift 4
EXTRA=("$@")
command -v valgrind > /dev/null || { echo "count_ab.sh: needs valgrind" >&2; exit 2; }
WORK=$(mktemp -d /tmp/scalefuse-count.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
one() {  # binary core side
  # SCALEFUSE_HUGE_PAGES=0: no re-exec for glibc's huge-page tunable, which valgrind cannot follow.
  SCALEFUSE_HUGE_PAGES=0 taskset -c "$2" valgrind --tool=cachegrind --cache-sim=no --branch-sim=yes \
    --cachegrind-out-file=/dev/null "$1" fuse "$INPUT" --config "$CONFIG" -o "$WORK/$3.ply" --job "$WORK/$3" \
    --integrate-only --threads 1 -q "${EXTRA[@]}" > "$WORK/$3.log" 2>&1
}
one "$A" 0 a &
pa=$!
one "$B" 1 b &
pb=$!
wait $pa
wait $pb
ta=$("$(dirname "$0")/field_hash.py" "$WORK/a/tiles")
tb=$("$(dirname "$0")/field_hash.py" "$WORK/b/tiles")
python3 - "$WORK" "$A" "$B" "$ta" "$tb" <<'PY'
import re, sys
work, a, b, ta, tb = sys.argv[1:6]
def counts(side):
    text = open(f"{work}/{side}.log").read()
    def get(label):
        m = re.search(label + r":\s+([\d,]+)", text)
        if not m:
            sys.exit(f"count_ab.sh: no '{label}' in the {side} run's output:\n{text[-2000:]}")
        return int(m.group(1).replace(",", ""))
    return {"instructions": get("I   refs"), "branches": get("Branches"), "mispredicts": get("Mispredicts")}
ca, cb = counts("a"), counts("b")
print(f"A = {a}\nB = {b}")
for k in ca:
    print(f"{k:>12}: A {ca[k]:>15,}  B {cb[k]:>15,}  B/A {cb[k] / ca[k]:.3f}")
print("tiles " + ("identical" if ta == tb else "different"))
PY
