// Ray casting against a triangle mesh with Embree (no home-made BVH).
// Rays are float (Embree's precision): distances agree with the exact
// ray-triangle distance to a few float ulps.
#pragma once

#include "range_image_mapping/triangle_mesh.h"

#include <cstddef>
#include <memory>

namespace range_image_mapping::simulation {

class RayCaster {
 public:
  // Copies the mesh into an Embree scene (robust traversal: rays through shared
  // edges never slip through). Throws std::invalid_argument for a vertex that
  // is not finite or an index out of range, std::runtime_error if Embree fails.
  explicit RayCaster(const TriangleMesh& mesh);
  ~RayCaster();
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  // For each ray: distance along the unit direction to the first hit within
  // [near, far], or NaN. Thread-safe (concurrent calls allowed). Rays go to
  // Embree in streams (rtcIntersect1M, coherent), so give neighbouring rays
  // together. normals (optional) receives the hit triangle's unit normal on
  // its counter-clockwise side (zero where nothing was hit).
  void cast(const Eigen::Vector3f* origins, const Eigen::Vector3f* directions, std::size_t count,
            float near, float far, float* distances, Eigen::Vector3f* normals = nullptr) const;
  // One ray at a time (rtcIntersect1): for single queries, and the baseline
  // the batched path is measured against.
  float castOne(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction, float near,
                float far, Eigen::Vector3f* normal = nullptr) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace range_image_mapping::simulation
