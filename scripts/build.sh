#!/usr/bin/env bash
# Configures and builds scalefuse (Release) into ./build; prints the program's path.
set -euo pipefail
cd "$(dirname "$0")/.."
JOBS="${JOBS:-$(nproc)}"
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$JOBS"
echo "built build/bin/scalefuse"
