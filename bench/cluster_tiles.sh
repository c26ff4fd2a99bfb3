#!/usr/bin/env bash
# Cluster plan on one machine (issue 5): for each tile count, plan the job, run every tile one
# after the other (as array tasks would run side by side on nodes), and report per tile the wall
# time, peak RSS, depth maps read and their bytes, then the sum against a single-process
# integration of the same job; with --merge, merge the last plan too (on one node); with --stages,
# run every later stage (regularize ... sort) on every tile too, then the merge (the last pass),
# and report each stage's slowest and summed tile times and each tile's peak RSS. Run by hand,
# never in CI.
#   bench/cluster_tiles.sh SCALEFUSE INPUT WORK "1 2 4 8" [--merge | --stages] [fuse options...]
# e.g. bench/cluster_tiles.sh build/bin/scalefuse /tmp/scalefuse-bench/city /tmp/ct "1 2 4 8" \
#        --config configs/mvs.toml
set -euo pipefail
BIN=$(readlink -f "$1") INPUT=$(readlink -f "$2") WORK=$3 COUNTS=$4
shift 4
MERGE=0 STAGES=0
if [ "${1:-}" = --merge ]; then MERGE=1; shift; fi
if [ "${1:-}" = --stages ]; then STAGES=1; shift; fi
LATER="regularize prepare tetrahedralize snap march number faces sort"
THREADS=${THREADS:-2} LIMIT=${LIMIT:-1.5G}
mkdir -p "$WORK"
for n in $COUNTS; do
  J=$WORK/t$n.job
  rm -rf "$J"
  /usr/bin/time -f "%e %M" -o "$WORK/t$n.plan.time" "$BIN" plan "$INPUT" --tiles "$n" --job "$J" -o "$WORK/t$n.ply" \
    --threads "$THREADS" -q "$@" > /dev/null
  for ((k = 0; k < n; k++)); do
    /usr/bin/time -f "%e %M" -o "$WORK/t$n.$k.time" "$BIN" run-tile "$J" --tile "$k" --threads "$THREADS" \
      --memory-limit "$LIMIT" --stats "$WORK/t$n.$k.json" -q > "$WORK/t$n.$k.log" 2>&1
  done
  if [ $STAGES = 1 ]; then
    for s in $LATER; do
      for ((k = 0; k < n; k++)); do
        /usr/bin/time -f "%e %M" -o "$WORK/t$n.$k.$s.time" "$BIN" run-tile "$J" --tile "$k" --stage "$s" \
          --threads "$THREADS" --memory-limit "$LIMIT" -q >> "$WORK/t$n.$k.log" 2>&1
      done
    done
    /usr/bin/time -f "%e %M" -o "$WORK/t$n.merge.time" "$BIN" merge "$J" --threads "$THREADS" \
      --memory-limit "$LIMIT" -q > "$WORK/t$n.merge.log" 2>&1
    du -sb "$J"/cluster/tile-*/exchange "$J"/cluster/tile-*/boundary > "$WORK/t$n.exchange.du" 2>/dev/null || true
    python3 - "$WORK" "$n" "$LATER" <<'PY'
import sys
work, n, later = sys.argv[1], int(sys.argv[2]), sys.argv[3].split()
def t(path):
    w, r = open(path).read().split()
    return float(w), int(r) / 1024
rows = [("integrate", [t(f"{work}/t{n}.{k}.time") for k in range(n)])]
rows += [(s, [t(f"{work}/t{n}.{k}.{s}.time") for k in range(n)]) for s in later]
print(f"{n} tiles, every stage on the tiles:")
print("  stage            slowest s   sum s   max peak MiB")
crit = work_sum = 0
for name, ts in rows:
    slow = max(w for w, _ in ts); total = sum(w for w, _ in ts); peak = max(r for _, r in ts)
    crit += slow; work_sum += total
    print(f"  {name:15s}  {slow:9.1f}  {total:6.1f}  {peak:12.0f}")
pw, _ = t(f"{work}/t{n}.plan.time"); mw, mr = t(f"{work}/t{n}.merge.time")
print(f"  plan {pw:.1f} s, merge (write) {mw:.1f} s, peak {mr:.0f} MiB")
print(f"  one node per tile: plan + slowest tile per stage + merge = {pw + crit + mw:.1f} s; all tiles' work {work_sum:.1f} s")
try:
    sizes = [int(l.split()[0]) for l in open(f"{work}/t{n}.exchange.du")]
    print(f"  exchange + boundary files left: {sum(sizes) / 2**20:.0f} MiB")
except OSError:
    pass
PY
  fi
  python3 - "$WORK" "$n" "$J" <<'PY'
import json, os, sys
work, n, job = sys.argv[1], int(sys.argv[2]), sys.argv[3]
plan = json.load(open(job + "/plan.json"))
import sqlite3
db = sqlite3.connect("file:" + job + "/job.sqlite?mode=ro", uri=True)
names = [r[0] for r in db.execute("select name from inputs order by idx")]
size = {i: os.path.getsize(p) for i, p in enumerate(names)}
pw, pr = open(f"{work}/t{n}.plan.time").read().split()
print(f"{n} tiles: plan {float(pw):.1f} s, peak {int(pr)/1024:.0f} MiB ({len(names)} depth maps read twice)")
print("  tile  depth maps  reads  read GiB   wall s  peak MiB  integrate s  sweep tiles")
tw = tr = tb = 0
for k, t in enumerate(plan["tiles"]):
    frames = t["frames"]
    if not frames:
        print(f"  {k:4d}  (empty)"); continue
    w, r = open(f"{work}/t{n}.{k}.time").read().split()
    s = json.load(open(f"{work}/t{n}.{k}.json"))
    # bounds pass (one read each) + plan and integration reads (stats)
    reads = len(frames) + s["frame_reads"]
    per = sum(size.values()) / len(size)  # frames are source indices (input.frame_step): the mean size
    gib = reads * per / 2**30
    print(f"  {k:4d}  {len(frames):10d}  {reads:5d}  {gib:8.2f}  {float(w):7.1f}  {int(r)/1024:8.0f}  {s['seconds']['integrate']:11.1f}  {s['tiles']:11d}")
    tw += float(w); tr += reads; tb += gib
print(f"  sum               {tr:5d}  {tb:8.2f}  {tw:7.1f}   (reads per depth map: {tr/len(names):.2f})")
PY
done
if [ $MERGE = 1 ]; then
  n=${COUNTS##* }
  /usr/bin/time -f "%e %M" -o "$WORK/t$n.merge.time" "$BIN" merge "$WORK/t$n.job" --threads "$THREADS" \
    --memory-limit "$LIMIT" --stats "$WORK/t$n.merge.json" -q > "$WORK/t$n.merge.log" 2>&1
  read -r w r < "$WORK/t$n.merge.time"
  echo "merge of $n tiles: $w s, peak $((r / 1024)) MiB"
fi
