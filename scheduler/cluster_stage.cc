#include "scheduler/cluster_stage.h"

#include <algorithm>
#include <optional>

#include "engine/error.h"
#include "engine/extract/brick_extract.h"
#include "engine/regularize.h"
#include "scheduler/job.h"
#include "storage/mailbox.h"
#include "storage/tile_store.h"

namespace sf {

namespace {

// Bit i of v -> bit i of the result, for every third bit (a Morton code's axis).
std::uint32_t every_third_bit(std::uint64_t v) {
  std::uint32_t out = 0;
  for (int i = 0; i < 21; ++i) out |= std::uint32_t((v >> (3 * i)) & 1) << i;
  return out;
}

std::vector<std::filesystem::path> exchange_folders(const TileStageContext& c) {
  std::vector<std::filesystem::path> f;
  for (std::size_t t = 0; t < c.plan.tiles.size(); ++t) f.push_back(tile_exchange_dir(c.job_dir, t));
  return f;
}

// A tile's integrated field, read brick by brick from its tiles (spilled; nothing is written).
struct TileField {
  std::optional<TileStore> store;
  BrickMap map;
  TileField(const TileStageContext& c, std::size_t tile) : map(c.plan.brick_level) {
    if (c.plan.tiles[tile].frames.empty()) return;  // nothing reaches it: no bricks
    const std::filesystem::path dir = tile_job_dir(c.job_dir, tile);
    const Job::Field f = Job::field(dir);
    store.emplace(dir / "tiles", tile_buffer_budget(c.memory_limit));
    map.attach_store(&*store, c.memory_limit);
    map.restore(f.manifest, f.max_generation);
  }
};

const char* const kBoundaryManifest = "boundary.blobs";

}  // namespace

const std::vector<std::string>& tile_stages() {
  static const std::vector<std::string> stages = [] {
    std::vector<std::string> s{"integrate"};
    for (const std::string& p : BrickExtraction::passes())
      if (p != "write") s.push_back(p);
    return s;
  }();
  return stages;
}

std::filesystem::path tile_boundary_dir(const std::filesystem::path& job_dir, std::size_t tile) {
  return tile_job_dir(job_dir, tile) / "boundary";
}
std::filesystem::path tile_exchange_dir(const std::filesystem::path& job_dir, std::size_t tile) {
  return tile_job_dir(job_dir, tile) / "exchange";
}

bool tile_stage_finished(const TileStageContext& c, std::size_t tile, const std::string& stage) {
  if (stage == "integrate") return std::filesystem::exists(tile_boundary_dir(c.job_dir, tile) / kBoundaryManifest);
  return std::filesystem::exists(tile_exchange_dir(c.job_dir, tile) / (stage + ".blobs"));
}

bool write_tile_boundary(const TileStageContext& c, std::size_t tile) {
  const std::filesystem::path dir = tile_boundary_dir(c.job_dir, tile);
  if (std::filesystem::exists(dir / kBoundaryManifest)) return false;
  std::filesystem::create_directories(dir);
  std::vector<BlobRecord> records;
  {
    TileField field(c, tile);
    Mailbox coarse(dir, "coarse"), faces(dir, "faces");
    coarse.keep_file();
    faces.keep_file();
    regularize_boundary(field.map, [&](BrickCoord b, std::vector<RawVoxel>&& low, std::vector<RawVoxel>&& face) {
      coarse.post(0, b.packed(), low);
      faces.post(b.packed(), b.packed(), face);
    });
    coarse.sync();
    faces.sync();
    for (const Mailbox::Blob& b : coarse.blobs()) records.push_back({"coarse", b});
    for (const Mailbox::Blob& b : faces.blobs()) records.push_back({"faces", b});
  }
  write_blob_manifest(dir / kBoundaryManifest, records);  // last: the boundary is complete
  return true;
}

bool run_tile_stage(const TileStageContext& c, std::size_t tile, const std::string& stage) {
  const auto& stages = tile_stages();
  if (std::find(stages.begin() + 1, stages.end(), stage) == stages.end())
    throw InputError("run-tile: no stage '" + stage + "' after integrate (stages: integrate, regularize, prepare, "
                     "tetrahedralize, snap, march, number, faces, sort)");
  if (tile_stage_finished(c, tile, stage)) return false;
  // Before anything is written (a tile's job is not opened for a stage it cannot run yet).
  const std::string& before = *(std::find(stages.begin(), stages.end(), stage) - 1);
  for (std::size_t t = 0; t < c.plan.tiles.size(); ++t)
    if (!tile_stage_finished(c, t, before))
      throw StageNotReady("tile " + std::to_string(t) + " has not finished stage " + before + "; run it first: scalefuse run-tile " +
                          std::filesystem::absolute(c.job_dir).string() + " --stage " + before + " --tile " +
                          std::to_string(t));
  if (stage != "regularize") {
    // Only the regularization reads the boundaries, and every tile has finished it.
    std::error_code ec;
    for (const char* box : {"coarse.box", "faces.box"}) std::filesystem::remove(tile_boundary_dir(c.job_dir, tile) / box, ec);
  }
  const ClusterPlan::Tile& own = c.plan.tiles[tile];
  const std::filesystem::path exchange = tile_exchange_dir(c.job_dir, tile);
  // The tile's job journal records the bricks each stage finished, so that a killed stage
  // resumes; a tile no depth map reaches owns no brick with voxels and needs none.
  std::optional<Job> job;
  ExtractJournal* journal = nullptr;
  if (!own.frames.empty()) {
    JobOptions jo;
    jo.dir = tile_job_dir(c.job_dir, tile);
    jo.checkpoint_seconds = c.checkpoint_seconds;
    jo.kill_in_extraction = c.kill_in_extraction;
    job.emplace(jo, "", "", "");
    journal = job->extraction(extraction_signature(c.options, c.plan.brick_level), exchange);
  }
  ExtractShare share;
  share.folders = exchange_folders(c);
  share.tile = tile;
  share.stage = stage;
  const BrickBox box = own.box;
  share.owns = [box](std::uint64_t code) {
    return box.contains({every_third_bit(code), every_third_bit(code >> 1), every_third_bit(code >> 2)});
  };
  std::filesystem::create_directories(exchange);
  BrickExtraction bricks(exchange, c.plan.root, c.plan.brick_level, c.options.extract, c.memory_limit, journal, &share);
  if (stage != "regularize") {
    MeshCollector unused;  // a tile's stage streams nothing
    bricks.run(unused, c.progress, nullptr);
    return true;
  }
  if (bricks.all_added_before()) {
    bricks.all_added();  // writes the manifest if a killed run had not
    return true;
  }
  // Every tile's boundary: the coarse voxels of all, the faces of this tile's neighbours.
  std::vector<Mailbox::Part> coarse_parts, face_parts;
  for (std::size_t t = 0; t < c.plan.tiles.size(); ++t) {
    const std::filesystem::path dir = tile_boundary_dir(c.job_dir, t);
    if (!std::filesystem::exists(dir / kBoundaryManifest))
      throw StageNotReady("tile " + std::to_string(t) + " has not finished stage integrate (no " +
                          (dir / kBoundaryManifest).string() + ")");
    Mailbox::Part coarse{dir / "coarse.box", {}}, faces{dir / "faces.box", {}};
    for (const BlobRecord& r : read_blob_manifest(dir / kBoundaryManifest))
      (r.box == "coarse" ? coarse : faces).blobs.push_back(r.blob);
    coarse_parts.push_back(std::move(coarse));
    face_parts.push_back(std::move(faces));
  }
  const Mailbox coarse(std::move(coarse_parts)), faces(std::move(face_parts));
  RegularizeBoundary boundary;
  boundary.coarse = coarse.collect<RawVoxel>(0);
  boundary.faces = [&](BrickCoord b, const std::function<void(const RawVoxel&)>& fn) {
    for (const RawVoxel& r : faces.collect<RawVoxel>(b.packed())) fn(r);
  };
  TileField field(c, tile);
  regularize_bricks(
      field.map, c.options.regularize, c.progress,
      [&](BrickCoord coord, std::vector<std::pair<VoxelKey, VoxelData>>&& voxels) {
        bricks.add(coord.packed(), surface_voxels(voxels));
      },
      [&](BrickCoord coord) { return bricks.added_before(coord.packed()); }, &boundary);
  bricks.all_added();
  return true;
}

StagesStatus tile_stages_status(const TileStageContext& c) {
  StagesStatus s;
  for (const std::string& stage : tile_stages()) {
    for (std::size_t t = 0; t < c.plan.tiles.size(); ++t)
      if (!tile_stage_finished(c, t, stage)) s.tiles.push_back(t);
    if (!s.tiles.empty()) {
      s.pending = stage;
      return s;
    }
  }
  return s;
}

void write_tiles_mesh(const TileStageContext& c, MeshStream& out, ExtractStats* stats) {
  ExtractShare share;
  share.folders = exchange_folders(c);
  share.tile = share.folders.size();  // none: the merge posts nothing
  share.stage = "write";
  share.owns = [](std::uint64_t) { return false; };
  BrickExtraction bricks(c.job_dir / "scratch", c.plan.root, c.plan.brick_level, c.options.extract, c.memory_limit,
                         nullptr, &share);
  bricks.run(out, c.progress, stats);
}

}  // namespace sf
