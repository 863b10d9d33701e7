// Reconstruction accuracy: a reconstructed surface (mesh or point cloud)
// against ground truth, as precision, recall and F-score at a distance
// threshold plus the Chamfer distance (the Tanks and Temples / Open3D
// definitions), on point samples of both surfaces.
#pragma once

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::evaluation {

// Meshes are sampled with range_image_mapping::sampleSurface: a grid of this spacing on
// every triangle (area-weighted, no clumps or holes), offset by the seed.
struct SurfaceSamplingOptions {
  double spacing_m = 0.0;  // for meshes, must be positive (rim eval mesh: a quarter of the threshold)
  uint32_t seed = 0;
  std::size_t max_points = 50'000'000;  // refuse meshes that would need more samples
};

// A surface read from a file: a PLY with faces or an OBJ (io::loadMeshFile)
// sampled over its area; a PLY without faces taken as its vertices.
struct SurfaceSample {
  std::vector<Eigen::Vector3f> points;
  bool from_mesh = false;
  std::size_t vertex_count = 0, triangle_count = 0;
  double area_m2 = 0;  // of the mesh; 0 for a point cloud
};

// Throws io::PlyFormatError or io::MeshFileError for a file that cannot be
// read, and std::invalid_argument for an empty surface, a non-finite point, or
// bad sampling options (also a mesh that needs more than max_points samples).
SurfaceSample loadSurfaceSample(const std::string& path, const SurfaceSamplingOptions& options);

// Distance from each query to its nearest reference point (a k-d tree,
// queries in parallel). Throws std::invalid_argument for an empty reference.
std::vector<float> nearestDistances(const std::vector<Eigen::Vector3f>& queries,
                                    const std::vector<Eigen::Vector3f>& reference);

// The share of distances below the threshold (0 for none): precision or
// recall from nearestDistances.
double shareBelow(const std::vector<float>& distances, double threshold);
// 2PR / (P + R), 0 when both are 0.
double fScore(double precision, double recall);

struct SurfaceMetrics {
  double threshold_m = 0;
  std::size_t estimate_points = 0, ground_truth_points = 0;
  double precision = 0;      // share of estimate points closer than threshold to the ground truth
  double recall = 0;         // share of ground-truth points closer than threshold to the estimate
  double f_score = 0;        // 2PR / (P + R)
  double f_score_paper = 0;  // PR / (P + R), the paper's Table 1 (half the standard one)
  double accuracy_mean_m = 0, accuracy_median_m = 0;          // estimate -> ground truth
  double completeness_mean_m = 0, completeness_median_m = 0;  // ground truth -> estimate
  double chamfer_m = 0;  // mean of the two mean distances
  std::vector<float> estimate_to_truth_m, truth_to_estimate_m;  // per point, for the maps
};

// Throws std::invalid_argument for an empty set or a threshold that is not positive.
SurfaceMetrics compareSurfaces(const std::vector<Eigen::Vector3f>& estimate,
                               const std::vector<Eigen::Vector3f>& ground_truth, double threshold_m);

}  // namespace range_image_mapping::evaluation
