#include "storage/tile_store.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

#include "engine/error.h"
#include "storage/tile_file.h"

namespace sf {

TileStore::TileStore(std::filesystem::path dir, std::size_t buffer_bytes)
    : dir_(std::move(dir)), buffers_(std::make_unique<TileBuffers>(buffer_bytes)) {
  std::error_code ec;
  std::filesystem::create_directories(dir_, ec);
  if (ec) throw InputError(dir_.string() + ": cannot create the tile folder: " + ec.message());
}

std::filesystem::path TileStore::path(BrickCoord c, std::uint64_t generation) const {
  return dir_ / ("b_" + std::to_string(c.x) + "_" + std::to_string(c.y) + "_" + std::to_string(c.z) + "." +
                 std::to_string(generation) + ".tile");
}

std::uint64_t TileStore::write(BrickCoord c, std::uint64_t generation, const VoxelTable& voxels) const {
  return write_tile(path(c, generation), c, voxels, false, buffers_.get());
}

void TileStore::sync() const {
  const int fd = ::open(dir_.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) throw InputError(dir_.string() + ": cannot open the tile folder: " + std::strerror(errno));
  const int rc = ::syncfs(fd);
  const int err = errno;
  ::close(fd);
  if (rc != 0) throw InputError(dir_.string() + ": cannot sync tiles to disk: " + std::strerror(err));
}

void TileStore::read(BrickCoord c, std::uint64_t generation, VoxelTable& voxels) const {
  const std::filesystem::path p = path(c, generation);
  BrickCoord got;
  try {
    got = read_tile(p, voxels, buffers_.get());
  } catch (const InputError& e) {
    throw DamagedTile(e.what(), c, generation);
  }
  if (got.x != c.x || got.y != c.y || got.z != c.z)
    throw DamagedTile(p.string() + ": damaged tile: holds another brick", c, generation);
}

void TileStore::remove(BrickCoord c, std::uint64_t generation) const {
  std::error_code ec;
  std::filesystem::remove(path(c, generation), ec);
}

std::size_t TileStore::remove_all_except(const std::set<std::pair<std::uint64_t, std::uint64_t>>& keep) const {
  std::size_t removed = 0;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir_, ec)) {
    const std::string name = entry.path().filename().string();
    unsigned x = 0, y = 0, z = 0;
    unsigned long long g = 0;
    int used = 0;
    bool ours = std::sscanf(name.c_str(), "b_%u_%u_%u.%llu.tile%n", &x, &y, &z, &g, &used) == 4;
    if (!ours) continue;
    const bool complete = std::size_t(used) == name.size();  // else a temporary file
    if (complete && keep.count({BrickCoord{x, y, z}.packed(), g})) continue;
    std::filesystem::remove(entry.path(), ec);
    ++removed;
  }
  return removed;
}

}  // namespace sf
