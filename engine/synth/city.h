#pragma once
// A synthetic city block the size of the paper's Citywall experiment (564 depth maps of 500x375,
// footprints varying > 16x), for the out-of-core benchmark (bench/city/).
//
// Layout, world metres, y up (the look_at convention): a ground slab over x in [-45, 45],
// z in [-30, 30]; a street front of buildings of different heights along the back (z < -15);
// `props` statues (copies of the given detailed meshes, turned and scaled, each on a plinth) in two
// rows across the plaza in front of them. Views:
//   far     distant views of the whole block from a ring around it, 25-45 m up (coarse footprint);
//   facade  views of the street front from the plaza, about 25 m away (middle footprint);
//   street  views of each statue from eye height, `street_distance` away, on an arc facing the
//           plaza (fine footprint: on the statues, > 16x finer than the far views' median at the
//           defaults).
// The scene's focus and close-up radius are those of statue 0 (for `eval --close-up`).
#include <vector>

#include "engine/mesh.h"
#include "engine/progress.h"
#include "engine/synth/synth.h"

namespace sf {

struct CityOptions {
  int props = 24;
  int far_views = 64;
  int facade_views = 20;
  int street_views = 480;  // shared evenly among the statues
  int width = 500, height = 375;
  double focal = 1.0;             // in image widths
  double street_distance = 3.0;   // metres from a street camera to its statue's axis
  double far_distance = 85.0;     // metres from a far camera to the block's centre
  double noise = 0.0;             // sigma in pixel footprints
  std::uint64_t seed = 1;         // statue turns, camera jitter, noise
  void check() const;             // throws InputError naming the bad field
};

// Builds the block from `props` (each normalized: its bounding box's height becomes the statue's)
// and renders every view. Throws InputError if a prop mesh has no triangle.
SyntheticScene render_city(const std::vector<Mesh>& props, const CityOptions& options, const ProgressFn& progress = {});

}  // namespace sf
