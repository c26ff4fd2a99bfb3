#!/usr/bin/env bash
# One command: install dependencies, build, and fuse the bundled example (the Stanford Bunny's ten
# real range scans, the paper's own experiment) with the laser preset.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
./scripts/build.sh
mkdir -p output
./build/bin/scalefuse fuse examples/stanford_bunny --config configs/laser.toml -o output/bunny.ply
