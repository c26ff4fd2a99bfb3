#!/usr/bin/env python3
"""Prints a 16-hex-digit hash of a job's field that does not depend on the tile format: sha256 of
each brick's raw payload (formats 4 to 7 store the same raw bytes; format 5 cuts them into chunks,
format 6 compresses each chunk's byte planes, format 7 their two halves apart),
keyed by brick. Two binaries that write different tile formats give the same hash for the same
field. Decompresses with the system's liblz4 (Debian package liblz4-1).
Usage: bench/field_hash.py JOB/tiles"""
import ctypes
import hashlib
import os
import re
import struct
import sys

lz4 = ctypes.CDLL("liblz4.so.1")
lz4.LZ4_decompress_safe.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_int]


def unpack(block, raw_size):
    out = ctypes.create_string_buffer(raw_size)
    n = lz4.LZ4_decompress_safe(block, out, len(block), raw_size)
    if n != raw_size:
        sys.exit(f"LZ4 block does not decompress to {raw_size} bytes")
    return out.raw


def raw_payload(path):
    data = open(path, "rb").read()
    version, raw_size = struct.unpack_from("<I", data, 8)[0], struct.unpack_from("<Q", data, 32)[0]
    if version == 4:
        return unpack(data[64:], raw_size)
    if version not in (5, 6, 7):
        sys.exit(f"{path}: tile format {version}, this script reads 4 to 7")
    parts, at = [], 64
    while at < len(data):
        raw_n, stored_n = struct.unpack_from("<II", data, at)
        if version == 7:  # planes 0-7 and 8-15 as two LZ4 blocks, behind the first's u32 size
            first = struct.unpack_from("<I", data, at + 16)[0]
            chunk = unpack(data[at + 20:at + 20 + first], raw_n // 2) + \
                unpack(data[at + 20 + first:at + 16 + stored_n], raw_n // 2)
        else:
            chunk = unpack(data[at + 16:at + 16 + stored_n], raw_n)
        if version >= 6:  # byte b of 16-byte unit i is at b n + i
            n = raw_n // 16
            units = bytearray(raw_n)
            for b in range(16):
                units[b::16] = chunk[b * n:(b + 1) * n]
            chunk = bytes(units)
        parts.append(chunk)
        at += 16 + stored_n
    return b"".join(parts)


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    lines = []
    for name in os.listdir(sys.argv[1]):
        if name.endswith(".tile"):
            brick = re.sub(r"\.[0-9]+\.tile$", "", name)
            lines.append(f"{hashlib.sha256(raw_payload(os.path.join(sys.argv[1], name))).hexdigest()}  {brick}\n")
    print(hashlib.sha256("".join(sorted(lines)).encode()).hexdigest()[:16])


if __name__ == "__main__":  # bench/block_occupancy.py imports raw_payload
    main()
