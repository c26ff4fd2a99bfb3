#pragma once
// The integration plan: the brick grid cut into tiles (boxes of bricks) whose fields fit a memory
// target, and for each tile the depth maps that can write into it.
//
// Integration then runs tile by tile (a sweep): each tile's bricks receive its depth maps in input
// order, are written once to their brick files and dropped, and no later tile of the sweep touches
// them. Each voxel still sums its contributions in depth-map order, so the field is the one a
// single pass gives, whatever the tiles; the disk traffic is one write per brick per sweep, and
// a depth map is read once per tile it reaches instead of bricks being paged in and out. Tiles
// are also the unit of work a cluster node takes.
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "engine/integrate.h"
#include "storage/brick_map.h"

namespace sf {

// Estimated memory of the field each brick will hold, from the surface cells of all depth maps
// (FrameReach::cells, merged: sorted, unique), plus the bytes bricks already hold (`existing`).
// Every brick of `touched` (FrameReach::bricks, merged) is in the result, if only with 0 bytes.
// A level-(l - 3) cell that the surface crosses holds about 8 x 8 x 1.5 surface cells of level l,
// each under a ramp of (1 + behind) x gamma cells, scaled to measured fields.
std::vector<std::pair<BrickCoord, double>> estimate_brick_bytes(
    const std::vector<VoxelKey>& cells, int brick_level, const IntegrateOptions& options,
    const std::vector<std::pair<BrickCoord, std::size_t>>& existing, const std::vector<std::uint64_t>& touched);

// Cuts the grid of 2^brick_level bricks per axis into boxes whose estimated bytes are at most
// `target` (a single brick may exceed it), by recursive bisection of the longest occupied axis at
// the weighted median. Every brick of the grid lies in exactly one box; boxes come in a
// spatially coherent order (left before right); boxes holding none of `bricks` are left out.
// With `within`, the boxes cut that box instead of the grid (every brick given must lie in it).
std::vector<BrickBox> cut_tiles(std::vector<std::pair<BrickCoord, double>> bricks, int brick_level, double target,
                                const BrickBox* within = nullptr);

// Cuts the grid into exactly `n` boxes of about equal estimated work (the weights of `bricks`):
// recursive bisection, each cut placed where the work before it is closest to the share of the
// boxes on that side, across the longest occupied axis unless another axis balances the sides
// better by more than 2 % of the work. Every brick of the grid lies in exactly one box
// (the cluster plan's tiles, docs/cluster.md); with fewer occupied bricks than `n`, some boxes are
// empty (lo == hi). Deterministic for a given input, whatever its order.
std::vector<BrickBox> split_tiles(std::vector<std::pair<BrickCoord, double>> bricks, int brick_level, std::size_t n);

// True if the box holds no brick.
bool empty_box(const BrickBox& b);

// The tile holding a brick, or tiles.size() if none.
std::size_t tile_of(const std::vector<BrickBox>& tiles, BrickCoord c);

}  // namespace sf
