#!/usr/bin/env bash
# One command: install dependencies, build, and run the whole test suite (prints ctest's summary).
# Tests that use real data read ../shared/data beside the repository.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
./scripts/build.sh
ctest --test-dir build --output-on-failure -j"${JOBS:-$(nproc)}" --timeout 900
