#!/usr/bin/env bash
# Prints a 16-hex-digit hash of a job's field: sha256 of each brick's tile, keyed by brick. Tile
# names carry generation numbers, which follow the plan's order, so they are left out: two plans
# that give the same field hash the same. Used by the A/B scripts.
# Usage: bench/tiles_hash.sh JOB/tiles
set -euo pipefail
[ $# -eq 1 ] || { sed -n 2,5p "$0" >&2; exit 2; }
cd "$1" && sha256sum -- * | sed -E 's/\.[0-9]+\.tile$//' | sort | sha256sum | cut -c1-16
