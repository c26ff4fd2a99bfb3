#!/usr/bin/env bash
# A job's final checkpoint (every brick written as a tile, then one syncfs) timed for two binaries,
# runs alternating: each run is a fresh `fuse --integrate-only --threads 1` pinned to one core under
# `strace -f -e trace=openat,syncfs`, and the time is that from the first tile's creation to the
# end of the last syncfs. strace adds its own cost to every system call of the process, so read
# the ratio, not the seconds. Prints each run's pair of times, the medians, B/A, and whether the
# fields are identical (bench/field_hash.py). Needs strace (apt-get install strace).
# Usage: [CORE=N] bench/checkpoint_ab.sh INPUT CONFIG RUNS BIN_A BIN_B [fuse args...]
#   e.g. bench/checkpoint_ab.sh /work/q/igea configs/mvs.toml 5 old/scalefuse build/bin/scalefuse
set -euo pipefail
[ $# -ge 5 ] || { sed -n 2,9p "$0" >&2; exit 2; }
INPUT=$1 CONFIG=$2 RUNS=$3 A=$4 B=$5
shift 5
CORE=${CORE:-1}
WORK=$(mktemp -d /tmp/scalefuse-ckpt.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
one() {  # binary side [fuse args...] -> seconds
  local bin=$1 side=$2
  shift 2
  rm -rf "$WORK/$side"
  taskset -c "$CORE" strace -f -tt -e trace=openat,syncfs -o "$WORK/$side.strace" "$bin" fuse "$INPUT" --config "$CONFIG" \
    -o "$WORK/$side.ply" --job "$WORK/$side" --integrate-only --threads 1 -q "$@" > /dev/null 2>&1
  python3 - "$WORK/$side.strace" <<'PY'
import sys
def sec(t):
    h, m, s = t.split(":")
    return int(h) * 3600 + int(m) * 60 + float(s)
first = last = None
for line in open(sys.argv[1]):
    p = line.split()
    if len(p) < 3:
        continue
    if "openat" in line and ".tile.tmp" in line and first is None:
        first = sec(p[1])
    if "syncfs(" in line and first is not None:
        last = sec(p[1])
if first is None or last is None:
    sys.exit(f"{sys.argv[1]}: no tile written or no syncfs after it")
print(f"{last - first:.4f}")
PY
}
ta=() tb=()
for i in $(seq "$RUNS"); do
  a=$(one "$A" a "$@")
  b=$(one "$B" b "$@")
  ta+=("$a") tb+=("$b")
  echo "run $i: A $a s, B $b s"
done
python3 - "${ta[*]}" "${tb[*]}" <<'PY'
import statistics, sys
a = [float(x) for x in sys.argv[1].split()]
b = [float(x) for x in sys.argv[2].split()]
ma, mb = statistics.median(a), statistics.median(b)
print(f"checkpoint median: A {ma:.3f} s, B {mb:.3f} s, B/A {mb / ma:.3f} (strace-inflated; compare the ratio)")
PY
if [ "$("$(dirname "$0")/field_hash.py" "$WORK/a/tiles")" = "$("$(dirname "$0")/field_hash.py" "$WORK/b/tiles")" ]; then
  echo "fields identical"
else
  echo "fields DIFFER"
fi
