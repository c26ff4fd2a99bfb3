# Shared by the cluster tests (sourced): a small multi-scale scene and its single-process mesh.
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
FUSE_ARGS=(--config "$ROOT/configs/mvs.toml" --set integrate.max_level=9)

fail() { echo "FAIL: $*" >&2; exit 1; }

# scene_and_reference BIN SHARED_DATA WORK: sets SCENE (a COLMAP workspace) and REF (its mesh
# fused by one process).
scene_and_reference() {
  local bin=$1 shared=$2 work=$3
  SCENE=$work/scene
  REF=$work/single.ply
  # 12 far 80x60 views of the whole bunny and 2 close 320x240 views of its head: footprints 8x apart.
  "$bin" synth "$shared/stanford_bunny/reconstruction/bun_zipper.ply" -o "$SCENE" --format colmap --far 12 \
    --far-size 80x60 --close 2 --close-size 320x240 --ratio 8 -q || fail "synth"
  "$bin" fuse "$SCENE" -o "$REF" -q --threads 2 "${FUSE_ARGS[@]}" || fail "single-process fuse"
  [ -s "$REF" ] || fail "no single-process mesh"
}

# same_bytes A B WHAT
same_bytes() {
  cmp -s "$1" "$2" || fail "$3: $2 differs from the single-process mesh $1"
  echo "ok: $3 is byte-identical to the single-process mesh ($(stat -c %s "$2") bytes)"
}
