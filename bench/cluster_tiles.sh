#!/usr/bin/env bash
# Cluster plan on one machine (issue 5): for each tile count, plan the job, run every tile one
# after the other (as array tasks would run side by side on nodes), and report per tile the wall
# time, peak RSS, depth maps read and their bytes, then the sum against a single-process
# integration of the same job; with --merge, merge the last plan too. Run by hand, never in CI.
#   bench/cluster_tiles.sh SCALEFUSE INPUT WORK "1 2 4 8" [--merge] [fuse options...]
# e.g. bench/cluster_tiles.sh build/bin/scalefuse /tmp/scalefuse-bench/city /tmp/ct "1 2 4 8" \
#        --config configs/mvs.toml
set -euo pipefail
BIN=$(readlink -f "$1") INPUT=$(readlink -f "$2") WORK=$3 COUNTS=$4
shift 4
MERGE=0
if [ "${1:-}" = --merge ]; then MERGE=1; shift; fi
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
    per = sum(size[f] for f in frames) / len(frames)
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
