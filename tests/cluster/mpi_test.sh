#!/usr/bin/env bash
# MPI mode (issue 5): `mpirun -n 3 scalefuse fuse ... --mpi --tiles 4` gives the single-process mesh
# byte for byte; a failing tile fails the run, names the tile and writes no mesh.
# Usage: mpi_test.sh SCALEFUSE SHARED_DATA WORK
set -euo pipefail
BIN=$1 SHARED=$2 W=$3
source "$(dirname "$0")/common.sh"
command -v mpirun >/dev/null || { echo "SKIP: mpirun not installed"; exit 77; }
rm -rf "$W" && mkdir -p "$W"
scene_and_reference "$BIN" "$SHARED" "$W"
MPIRUN=(timeout 600 mpirun -n 3 --oversubscribe)
[ "$(id -u)" = 0 ] && MPIRUN+=(--allow-run-as-root)
# OpenMPI needs a working loopback only; keep it off other interfaces.
MPIRUN+=(--mca btl self,tcp --mca btl_tcp_if_include lo --mca oob_tcp_if_include lo)

"${MPIRUN[@]}" "$BIN" fuse "$SCENE" -o "$W/mpi.ply" --job "$W/mpi.job" --mpi --tiles 4 --threads 1 -q "${FUSE_ARGS[@]}" \
  > "$W/mpi.log" 2>&1 || { cat "$W/mpi.log"; fail "mpirun -n 3 fuse --mpi"; }
same_bytes "$REF" "$W/mpi.ply" "mpirun -n 3, 4 tiles"

set +e
"${MPIRUN[@]}" -x SCALEFUSE_TEST_FAIL_TILE=2 "$BIN" fuse "$SCENE" -o "$W/bad.ply" --job "$W/bad.job" --mpi --tiles 4 \
  --threads 1 -q "${FUSE_ARGS[@]}" > "$W/bad.log" 2>&1
rc=$?
set -e
[ $rc -ne 0 ] || { cat "$W/bad.log"; fail "a failing tile did not fail the MPI run"; }
grep -q "tile 2 failed on rank" "$W/bad.log" || { cat "$W/bad.log"; fail "the failing tile is not named"; }
[ ! -e "$W/bad.ply" ] || fail "a mesh was written although a tile failed"
echo "ok: a failing tile fails the MPI run (exit $rc): $(grep -m1 -o 'tile 2 failed on rank [0-9]*' "$W/bad.log")"
