// Dense point samples of a triangle mesh's surface: the ground truth of
// reconstruction metrics (evaluation) and of the simulator's scenes.
#pragma once

#include "range_image_mapping/triangle_mesh.h"

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace range_image_mapping {

struct SurfaceSampleOptions {
  // Distance between neighbouring samples: each triangle is sampled on a square
  // grid of this step in its own plane, so the density is 1 / spacing^2 per m^2
  // everywhere (area-weighted) without the clumps and holes of random sampling.
  double spacing_m = 0.02;
  uint32_t seed = 1;  // the grid's random offset per triangle (makes the count unbiased)
};

// A part of space the samples are restricted to (simulation::SeenRegion: what
// a sensor saw). Each triangle is walked in square tiles of tileEdge() metres;
// a tile is skipped when mayBeNear says no, and a sample kept when isNear.
class SurfaceRegion {
 public:
  virtual ~SurfaceRegion() = default;
  virtual bool isNear(const Eigen::Vector3f& point) const = 0;
  // Cheap test for a whole patch: false when no point within radius of centre
  // is near (true does not promise one is).
  virtual bool mayBeNear(const Eigen::Vector3f& centre, float radius) const = 0;
  virtual double tileEdge() const = 0;
};

// Every sample of the mesh. Deterministic for a seed, also when run in
// parallel. Throws std::invalid_argument for a spacing that is not positive
// and finite, or a triangle with a vertex index out of range.
std::vector<Eigen::Vector3f> sampleSurface(const TriangleMesh& mesh, const SurfaceSampleOptions& options);

// The same samples restricted to a region; the work grows with the area near
// the region, not the mesh's.
std::vector<Eigen::Vector3f> sampleSurface(const TriangleMesh& mesh, const SurfaceSampleOptions& options,
                                           const SurfaceRegion& region);

}  // namespace range_image_mapping
