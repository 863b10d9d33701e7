#include "range_image_mapping/evaluation/surface_metrics.h"

#include "range_image_mapping/io/mesh_file.h"
#include "range_image_mapping/io/ply.h"
#include "range_image_mapping/surface_sampling.h"

#include <nanoflann.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

namespace range_image_mapping::evaluation {
namespace {

// The view nanoflann needs of a point vector.
struct PointSetAdaptor {
  const std::vector<Eigen::Vector3f>& points;
  std::size_t kdtree_get_point_count() const { return points.size(); }
  float kdtree_get_pt(std::size_t index, std::size_t axis) const { return points[index][static_cast<int>(axis)]; }
  template <typename BoundingBox>
  bool kdtree_get_bbox(BoundingBox&) const {
    return false;  // let nanoflann compute it
  }
};
// The tree's index type is given, not defaulted: nanoflann 1.3 (Debian
// bullseye) defaults it to size_t, 1.4 to uint32_t, and knnSearch takes a
// pointer to it.
using KdTreeIndex = uint32_t;
using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, PointSetAdaptor>,
                                                   PointSetAdaptor, 3, KdTreeIndex>;

std::string lowerCaseExtension(const std::string& path) {
  std::string extension = std::filesystem::path(path).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return extension;
}

// Whether a PLY header declares faces: a mesh is sampled over its area, a
// cloud is taken as it is. Only the header's "element" lines are looked at;
// the file itself is parsed by io::loadMeshFile or io::readPlyPoints.
bool plyDeclaresFaces(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) throw io::PlyFormatError("PLY: cannot open " + path);
  std::string line;
  while (std::getline(file, line)) {
    std::istringstream words(line);
    std::string keyword, name;
    long long count = 0;
    words >> keyword;
    if (keyword == "end_header") break;
    if (keyword == "element" && (words >> name >> count) && name == "face" && count > 0) return true;
  }
  return false;
}

void requireFinite(const std::vector<Eigen::Vector3f>& points, const std::string& what) {
  for (std::size_t i = 0; i < points.size(); ++i)
    if (!points[i].allFinite())
      throw std::invalid_argument(what + " has a point that is not finite (index " +
                                  std::to_string(i) + ")");
}

double meanOf(const std::vector<float>& values) {
  double sum = 0;
  for (const float value : values) sum += value;
  return sum / static_cast<double>(values.size());
}

double medianOf(std::vector<float> values) {
  const std::size_t middle = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(middle), values.end());
  const double upper = values[middle];
  if (values.size() % 2 == 1) return upper;
  const double lower = *std::max_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(middle));
  return 0.5 * (lower + upper);
}

}  // namespace

double shareBelow(const std::vector<float>& distances, double threshold) {
  if (distances.empty()) return 0.0;
  const auto below = std::count_if(distances.begin(), distances.end(),
                                   [threshold](float distance) { return distance < threshold; });
  return static_cast<double>(below) / static_cast<double>(distances.size());
}

double fScore(double precision, double recall) {
  const double sum = precision + recall;
  return sum > 0 ? 2.0 * precision * recall / sum : 0.0;
}

SurfaceSample loadSurfaceSample(const std::string& path, const SurfaceSamplingOptions& options) {
  const std::string extension = lowerCaseExtension(path);
  SurfaceSample sample;
  if (extension == ".obj" || (extension == ".ply" && plyDeclaresFaces(path))) {
    const TriangleMesh mesh = io::loadMeshFile(path);
    sample.from_mesh = true;
    sample.vertex_count = mesh.vertices.size();
    sample.triangle_count = mesh.triangles.size();
    sample.area_m2 = mesh.area();
    if (!(options.spacing_m > 0) || !std::isfinite(options.spacing_m))
      throw std::invalid_argument(path + ": the sample spacing must be positive, not " +
                                  std::to_string(options.spacing_m));
    if (!(sample.area_m2 > 0))
      throw std::invalid_argument(path + ": the mesh has no area (" +
                                  std::to_string(sample.triangle_count) + " triangles)");
    const double expected = sample.area_m2 / (options.spacing_m * options.spacing_m);
    if (expected > static_cast<double>(options.max_points))
      throw std::invalid_argument(path + ": " + std::to_string(sample.area_m2) + " m2 at a spacing of " +
                                  std::to_string(options.spacing_m) + " m needs " +
                                  std::to_string(static_cast<long long>(expected)) +
                                  " samples, more than " + std::to_string(options.max_points) +
                                  "; choose a larger spacing");
    SurfaceSampleOptions sampling;
    sampling.spacing_m = options.spacing_m;
    sampling.seed = options.seed;
    sample.points = sampleSurface(mesh, sampling);
  } else if (extension == ".ply") {
    sample.points = io::readPlyPoints(path);
    sample.vertex_count = sample.points.size();
  } else {
    throw std::invalid_argument(path + ": unknown surface file type \"" + extension +
                                "\"; expected a PLY point cloud or mesh, or an OBJ mesh");
  }
  if (sample.points.empty())
    throw std::invalid_argument(path + ": the surface has no points");
  requireFinite(sample.points, path);
  return sample;
}

std::vector<float> nearestDistances(const std::vector<Eigen::Vector3f>& queries,
                                    const std::vector<Eigen::Vector3f>& reference) {
  if (reference.empty()) throw std::invalid_argument("nearestDistances: the reference set is empty");
  if (reference.size() >= std::numeric_limits<KdTreeIndex>::max())
    throw std::invalid_argument("nearestDistances: more than 2^32 reference points");
  const PointSetAdaptor adaptor{reference};
  KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
#if NANOFLANN_VERSION < 0x140
  tree.buildIndex();  // nanoflann 1.4 builds it in the constructor, 1.3 (bullseye) does not
#endif
  std::vector<float> distances(queries.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, queries.size(), 4096),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      KdTreeIndex index = 0;
                      float squared = 0;
                      for (std::size_t i = range.begin(); i != range.end(); ++i) {
                        tree.knnSearch(queries[i].data(), 1, &index, &squared);
                        distances[i] = std::sqrt(squared);
                      }
                    });
  return distances;
}

SurfaceMetrics compareSurfaces(const std::vector<Eigen::Vector3f>& estimate,
                               const std::vector<Eigen::Vector3f>& ground_truth, double threshold_m) {
  if (!(threshold_m > 0) || !std::isfinite(threshold_m))
    throw std::invalid_argument("compareSurfaces: the threshold must be positive, not " +
                                std::to_string(threshold_m));
  if (estimate.empty()) throw std::invalid_argument("compareSurfaces: the estimate has no points");
  if (ground_truth.empty()) throw std::invalid_argument("compareSurfaces: the ground truth has no points");
  requireFinite(estimate, "compareSurfaces: the estimate");
  requireFinite(ground_truth, "compareSurfaces: the ground truth");

  SurfaceMetrics metrics;
  metrics.threshold_m = threshold_m;
  metrics.estimate_points = estimate.size();
  metrics.ground_truth_points = ground_truth.size();
  metrics.estimate_to_truth_m = nearestDistances(estimate, ground_truth);
  metrics.truth_to_estimate_m = nearestDistances(ground_truth, estimate);

  metrics.precision = shareBelow(metrics.estimate_to_truth_m, threshold_m);
  metrics.recall = shareBelow(metrics.truth_to_estimate_m, threshold_m);
  metrics.f_score = fScore(metrics.precision, metrics.recall);
  metrics.f_score_paper = 0.5 * metrics.f_score;
  metrics.accuracy_mean_m = meanOf(metrics.estimate_to_truth_m);
  metrics.accuracy_median_m = medianOf(metrics.estimate_to_truth_m);
  metrics.completeness_mean_m = meanOf(metrics.truth_to_estimate_m);
  metrics.completeness_median_m = medianOf(metrics.truth_to_estimate_m);
  metrics.chamfer_m = 0.5 * (metrics.accuracy_mean_m + metrics.completeness_mean_m);
  return metrics;
}

}  // namespace range_image_mapping::evaluation
