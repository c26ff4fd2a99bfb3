#!/usr/bin/env python3
"""How full a job's voxel blocks are, per level: the evidence for (or against) a smaller block
shape. Reads the job's checkpoint tiles (formats 4 to 7, through bench/field_hash.py's reader) and
its brick level (job.sqlite), and prints per level: blocks, block edge, present voxels, the share
of a block's slots they fill, and for 4^3 blocks how many of their eight 2^3 octants hold a
present voxel and how full those are; then the slots (16 bytes each, all zeroed when a block is
made) the field would hold in the tiles' 4^3 blocks ("now": the table's blocks until session 41)
and holds in 2^3 blocks (the table's since). Headers, index slots and allocator chunks are not
counted (they grow with the block count).
Usage: bench/block_occupancy.py JOB"""
import os
import sqlite3
import struct
import sys

from field_hash import raw_payload  # the tile reader (formats 4 to 7)

if len(sys.argv) != 2:
    sys.exit(__doc__)
job = sys.argv[1]
brick_level = int(sqlite3.connect(os.path.join(job, "job.sqlite")).execute(
    "SELECT value FROM meta WHERE key = 'brick_level'").fetchone()[0])

# Bit masks of the eight 2^3 octants of a 4^3 block (x fastest).
OCTANTS = []
for oz in range(2):
    for oy in range(2):
        for ox in range(2):
            m = 0
            for z in range(2):
                for y in range(2):
                    for x in range(2):
                        m |= 1 << (((2 * oz + z) * 4 + 2 * oy + y) * 4 + 2 * ox + x)
            OCTANTS.append(m)

levels = {}  # level -> [blocks, present voxels, non-empty octants]
tiles = os.path.join(job, "tiles")
for name in os.listdir(tiles):
    if not name.endswith(".tile"):
        continue
    payload = raw_payload(os.path.join(tiles, name))
    at = 0
    while at < len(payload):
        key, mask = struct.unpack_from("<QQ", payload, at)
        level = key >> 57
        present = bin(mask).count("1")
        s = levels.setdefault(level, [0, 0, 0])
        s[0] += 1
        s[1] += present
        s[2] += sum(1 for m in OCTANTS if mask & m)
        at += 16 * (1 + present)

print(f"brick level {brick_level}")
print("level  blocks  edge  present voxels  slots filled  non-empty 2^3 octants  octants filled")
now = smaller = 0
for level in sorted(levels):
    blocks, present, octants = levels[level]
    k = min(max(level - brick_level, 0), 2)
    slots = blocks << (3 * k)
    now += slots
    smaller += octants * 8 if k == 2 else slots
    line = f"{level:5d} {blocks:7d} {1 << k:5d} {present:15d} {present / slots:13.2f}"
    if k == 2:
        line += f" {octants:22d} {present / (8 * octants):15.2f}"
    print(line)
print(f"slots now {now} ({now * 16 / 2**20:.1f} MiB); in 2^3 blocks {smaller} ({smaller * 16 / 2**20:.1f} MiB, "
      f"{smaller / now:.2f} of now)")
