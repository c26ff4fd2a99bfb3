#pragma once
// Synthetic multi-scale scenes: a mesh ray-cast into registered depth maps with known geometry.
//
// The setup follows the paper's notes (docs: /work/shared/paper/NOTES.md): a ~1.6 m object seen by
// many low-resolution "far" views from all around (coarse footprint) and a few high-resolution
// "close" views of one small region (fine footprint, 8-16x smaller).
//
// Glossary
//   normalized frame  the mesh after scaling it to `size` and centring its bounding box at the
//                     origin; every camera, depth and point of a scene is in this frame.
//   footprint         of a pixel: z / sqrt(fx * fy), the width of the fronto-parallel square that
//                     projects onto it (DepthFrame's definition).
//   coarse footprint  median footprint over all valid pixels of the far views.
//   fine footprint    the same over the close views.
//   focus             the surface point the close views look at.
//   close radius      radius around the focus that every close view sees (see SyntheticScene).
//
// Camera conventions are DepthFrame's: Sensor R,t world -> camera, x right, y down, z forward;
// pixel (col,row) is centred at (col + 0.5, row + 0.5).
#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "engine/depth_frame.h"
#include "engine/mesh.h"
#include "engine/progress.h"

namespace sf {

struct SynthOptions {
  // Normalization: the mesh is scaled so that `size_measure` of its bounding box equals `size`
  // (metres) and its bounding box is centred at the origin.
  enum class SizeMeasure { Extent, Diagonal };  // largest side / diagonal of the bounding box
  double size = 1.6;
  SizeMeasure size_measure = SizeMeasure::Extent;

  // Far views: on a sphere around the object (Fibonacci directions), looking at the origin, at the
  // distance where the object's bounding sphere spans `far_fill` of the smaller image side.
  int far_views = 24;
  int far_width = 160, far_height = 120;
  double far_fill = 0.9;

  // Close views: on a cone of half-angle `close_tilt_deg` around the surface normal at the focus
  // (a single close view looks straight along the normal), looking at the focus, at the distance
  // where their median footprint is coarse footprint / `footprint_ratio` within 2% (so close
  // views need far views).
  int close_views = 4;
  int close_width = 640, close_height = 480;
  double footprint_ratio = 14.0;  // NOTES: 14.5 mm / 1.05 mm
  double close_tilt_deg = 20.0;
  // Focus in the normalized frame (snapped to the nearest surface point). Default: the vertex with
  // the largest y (the top of an upright head).
  std::optional<Eigen::Vector3d> focus;

  // Focal length in units of the image width, for every view (1.0: 53.1 degrees horizontally).
  double focal = 1.0;

  // One resolution for all views (RGB-D stores a single K): far views are rendered at the close
  // views' size and focal length, each moved back along its axis so that its median footprint
  // stays what it would be at far_width x far_height.
  bool uniform_resolution = false;

  // Gaussian depth noise along the optical axis with sigma = noise * the pixel's footprint.
  double noise = 0.0;
  std::uint64_t seed = 1;

  void check() const;  // throws InputError naming the bad field and its value
};

struct SynthView {
  std::string name;  // "far_000", "close_00"
  bool close = false;
  int width = 0, height = 0;
  Sensor sensor;     // perspective
  std::vector<float> depth;           // z-depth in metres, row-major; 0 = no surface (noise applied)
  std::vector<Rgb8> colour;           // row-major; black where depth is 0
  std::vector<Eigen::Vector3f> normal;  // world-space unit surface normal; zero where depth is 0
  double median_footprint = 0;        // metres, over valid pixels (before noise)
  std::size_t valid_pixels = 0;

  std::size_t size() const { return std::size_t(width) * std::size_t(height); }
};

struct SyntheticScene {
  SynthOptions options;
  Mesh reference;                      // the normalized mesh (vertices, faces, colours)
  // Normalization: p_normalized = scale * (p_source - source_centre).
  Eigen::Vector3d source_centre = Eigen::Vector3d::Zero();
  double scale = 1.0;
  Eigen::Vector3d focus = Eigen::Vector3d::Zero();
  Eigen::Vector3d focus_normal = Eigen::Vector3d::UnitY();
  // Radius of the sphere around the focus whose cross-section at the focus depth fits, with a 20%
  // margin, inside every close view's image (0 without close views): the close-up evaluation
  // region.
  double close_radius = 0;
  double coarse_footprint = 0, fine_footprint = 0;  // metres (fine is 0 without close views)
  std::vector<SynthView> views;        // far views first, then close views
};

// Renders the scene. Throws InputError if the mesh has no (non-degenerate) triangle or if a view
// sees nothing; progress stage "render" counts views. Pixels are cast with tbb::parallel_for in
// the caller's task arena (no arena or thread pool of its own); the result does not depend on the
// number of threads (noise is drawn per view, serially, from seed and view index).
SyntheticScene render_scene(const Mesh& mesh, const SynthOptions& options, const ProgressFn& progress = {});

// Ray-casts one view of `mesh` (already in the frame of `view.sensor`): fills depth (z), colour,
// normal, median_footprint and valid_pixels of `view`, whose name/size/sensor are set. No noise.
// Colour: the mesh's vertex colours interpolated if it has any, else the world normal mapped to RGB.
// Exposed for tests and tools; render_scene builds the query structure once for all views.
void render_view(const Mesh& mesh, SynthView& view);

// Ray-casts every view of `views` (name, size and sensor set) against one query structure built
// once for `mesh`, as render_view does; views that see nothing keep valid_pixels == 0. Progress
// stage "render" counts views.
void render_views(const Mesh& mesh, std::vector<SynthView>& views, const ProgressFn& progress = {});

// Gaussian depth noise along the optical axis, sigma = noise * the pixel's footprint, drawn per
// view from splitmix(seed, view index) so that it does not depend on threads.
void add_depth_noise(std::vector<SynthView>& views, double noise, std::uint64_t seed);

// Camera at `centre` looking at `target`, image y pointing along -up as far as possible.
Sensor look_at(const Eigen::Vector3d& centre, const Eigen::Vector3d& target, double focal_px, int width,
               int height, const Eigen::Vector3d& up = Eigen::Vector3d::UnitY());

}  // namespace sf
