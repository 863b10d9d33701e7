#include "range_image_mapping/evaluation/surface_metrics.h"

#include "range_image_mapping/evaluation/report.h"
#include "range_image_mapping/io/ply.h"
#include "range_image_mapping/simulation/mesh_primitives.h"
#include "range_image_mapping/surface_sampling.h"

#include "error_text.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>

namespace range_image_mapping::evaluation {
namespace {


std::string temporaryPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("rim_surface_metrics_test_" + name)).string();
}

using test::contains;
using test::errorOf;

// A width x depth rectangle in the plane z = height.
TriangleMesh plane(float width, float depth, float height) {
  return simulation::makeQuad(Eigen::Vector3f(0, 0, height), Eigen::Vector3f(width, 0, 0),
                              Eigen::Vector3f(0, depth, 0));
}

// The sampler rim eval mesh uses (range_image_mapping::sampleSurface).
std::vector<Eigen::Vector3f> sampleSurface(const TriangleMesh& mesh, double spacing, uint32_t seed) {
  SurfaceSampleOptions options;
  options.spacing_m = spacing;
  options.seed = seed;
  return range_image_mapping::sampleSurface(mesh, options);
}

std::vector<Eigen::Vector3f> randomPoints(std::size_t count, uint32_t seed) {
  std::mt19937 generator(seed);
  std::uniform_real_distribution<float> uniform(-5.0f, 5.0f);
  std::vector<Eigen::Vector3f> points(count);
  for (Eigen::Vector3f& point : points) point = Eigen::Vector3f(uniform(generator), uniform(generator), uniform(generator));
  return points;
}

// ---------------------------------------------------------------- nearest neighbours

TEST(NearestDistances, MatchBruteForce) {
  const std::vector<Eigen::Vector3f> reference = randomPoints(3000, 1);
  const std::vector<Eigen::Vector3f> queries = randomPoints(500, 2);
  const std::vector<float> distances = nearestDistances(queries, reference);
  ASSERT_EQ(distances.size(), queries.size());
  for (std::size_t i = 0; i < queries.size(); ++i) {
    float nearest = std::numeric_limits<float>::infinity();
    for (const Eigen::Vector3f& point : reference) nearest = std::min(nearest, (point - queries[i]).norm());
    EXPECT_NEAR(distances[i], nearest, 1e-5f) << i;
  }
  EXPECT_TRUE(contains(errorOf([&] { nearestDistances(queries, {}); }), "reference set is empty"));
}

// ---------------------------------------------------------------- precision, recall

TEST(CompareSurfaces, AMeshAgainstItselfHasFScoreOne) {
  const TriangleMesh mesh = simulation::makeSphere(Eigen::Vector3f(0, 0, 0), 3.0f, 4);
  const double threshold = 0.15;
  // Different seeds: two independent samples of the same surface.
  const SurfaceMetrics metrics =
      compareSurfaces(sampleSurface(mesh, threshold / 4, 1), sampleSurface(mesh, threshold / 4, 2), threshold);
  EXPECT_EQ(metrics.precision, 1.0);
  EXPECT_EQ(metrics.recall, 1.0);
  EXPECT_EQ(metrics.f_score, 1.0);
  EXPECT_EQ(metrics.f_score_paper, 0.5);
  EXPECT_LT(metrics.chamfer_m, threshold / 4);
  // The same sample: exactly zero.
  const std::vector<Eigen::Vector3f> sample = sampleSurface(mesh, threshold / 4, 1);
  EXPECT_EQ(compareSurfaces(sample, sample, threshold).chamfer_m, 0.0);
}

TEST(CompareSurfaces, AShiftedPlaneIsWithinOrBeyondTheThreshold) {
  const double threshold = 0.1, spacing = threshold / 4;
  const std::vector<Eigen::Vector3f> truth = sampleSurface(plane(4, 3, 0), spacing, 1);
  for (const double shift : {0.05, 0.08, 0.12, 0.3}) {
    const std::vector<Eigen::Vector3f> shifted =
        sampleSurface(plane(4, 3, static_cast<float>(shift)), spacing, 2);
    const SurfaceMetrics metrics = compareSurfaces(shifted, truth, threshold);
    const double expected = shift < threshold ? 1.0 : 0.0;
    EXPECT_EQ(metrics.precision, expected) << shift;
    EXPECT_EQ(metrics.recall, expected) << shift;
    EXPECT_EQ(metrics.f_score, expected) << shift;
    // Samples are not opposite each other: a little more than the shift on average.
    EXPECT_GE(metrics.chamfer_m, shift - 1e-6) << shift;
    EXPECT_NEAR(metrics.chamfer_m, shift, 0.02 * shift + 0.002) << shift;
    EXPECT_NEAR(metrics.accuracy_median_m, shift, 0.02 * shift + 0.002) << shift;
  }
}

TEST(CompareSurfaces, HalfTheGroundTruthMissingGivesRecallOneHalf) {
  const double threshold = 0.03;
  const std::vector<Eigen::Vector3f> truth = sampleSurface(plane(2, 1, 0), threshold / 4, 1);
  const std::vector<Eigen::Vector3f> half = sampleSurface(plane(1, 1, 0), threshold / 4, 2);
  const SurfaceMetrics metrics = compareSurfaces(half, truth, threshold);
  EXPECT_EQ(metrics.precision, 1.0);
  // Ground truth up to one threshold beyond the edge still counts as found.
  EXPECT_NEAR(metrics.recall, (1.0 + threshold) / 2.0, 0.01);
  const double recall = metrics.recall;
  EXPECT_NEAR(metrics.f_score, 2 * recall / (1 + recall), 1e-12);
  EXPECT_NEAR(metrics.f_score_paper, recall / (1 + recall), 1e-12);
}

TEST(CompareSurfaces, FarOutliersHalveThePrecision) {
  const std::vector<Eigen::Vector3f> truth = sampleSurface(plane(2, 2, 0), 0.02, 1);
  std::vector<Eigen::Vector3f> estimate = truth;
  for (const Eigen::Vector3f& point : truth) estimate.push_back(point + Eigen::Vector3f(0, 0, 5));
  const SurfaceMetrics metrics = compareSurfaces(estimate, truth, 0.1);
  EXPECT_DOUBLE_EQ(metrics.precision, 0.5);
  EXPECT_DOUBLE_EQ(metrics.recall, 1.0);
  EXPECT_DOUBLE_EQ(metrics.f_score, 2.0 / 3.0);
  EXPECT_DOUBLE_EQ(metrics.f_score_paper, 1.0 / 3.0);
  EXPECT_NEAR(metrics.accuracy_mean_m, 2.5, 1e-5);
  EXPECT_EQ(metrics.completeness_mean_m, 0.0);
  EXPECT_NEAR(metrics.chamfer_m, 1.25, 1e-5);
}

TEST(CompareSurfaces, RejectsBadInput) {
  const std::vector<Eigen::Vector3f> points = randomPoints(10, 1);
  EXPECT_TRUE(contains(errorOf([&] { compareSurfaces(points, points, 0.0); }), "threshold must be positive"));
  EXPECT_TRUE(contains(errorOf([&] { compareSurfaces({}, points, 0.1); }), "estimate has no points"));
  EXPECT_TRUE(contains(errorOf([&] { compareSurfaces(points, {}, 0.1); }), "ground truth has no points"));
  std::vector<Eigen::Vector3f> with_nan = points;
  with_nan[3].y() = std::nanf("");
  EXPECT_TRUE(contains(errorOf([&] { compareSurfaces(with_nan, points, 0.1); }), "not finite (index 3)"));
}

// ---------------------------------------------------------------- files

TEST(LoadSurfaceSample, SamplesMeshesAndTakesCloudsAsTheyAre) {
  const TriangleMesh mesh = plane(2, 1, 0);
  const std::string mesh_path = temporaryPath("plane.ply");
  io::writePlyMesh(mesh_path, mesh.vertices, {}, mesh.triangles);
  SurfaceSamplingOptions options;
  options.spacing_m = 0.01;
  options.seed = 3;
  const SurfaceSample sampled = loadSurfaceSample(mesh_path, options);
  EXPECT_TRUE(sampled.from_mesh);
  EXPECT_EQ(sampled.triangle_count, 2u);
  EXPECT_NEAR(sampled.area_m2, 2.0, 1e-6);
  EXPECT_EQ(sampled.points, sampleSurface(mesh, 0.01, 3));

  const std::string cloud_path = temporaryPath("cloud.ply");
  const std::vector<Eigen::Vector3f> cloud = randomPoints(100, 4);
  io::writePlyPointCloud(cloud_path, cloud);
  const SurfaceSample taken = loadSurfaceSample(cloud_path, options);
  EXPECT_FALSE(taken.from_mesh);
  EXPECT_EQ(taken.points, cloud);

  options.spacing_m = 0;
  EXPECT_TRUE(contains(errorOf([&] { loadSurfaceSample(mesh_path, options); }), "spacing must be positive"));
  options.spacing_m = 0.001;
  options.max_points = 1000;  // 2 m2 would need 2 million
  EXPECT_TRUE(contains(errorOf([&] { loadSurfaceSample(mesh_path, options); }), "more than 1000; choose a larger spacing"));
  options.max_points = 50'000'000;
  EXPECT_TRUE(contains(errorOf([&] { loadSurfaceSample(temporaryPath("x.xyz"), options); }),
                       "unknown surface file type \".xyz\""));
  io::writePlyPointCloud(cloud_path, {});
  EXPECT_TRUE(contains(errorOf([&] { loadSurfaceSample(cloud_path, options); }), "no points"));
  std::ofstream(cloud_path) << "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n1\n";
  EXPECT_THROW(loadSurfaceSample(cloud_path, options), io::PlyFormatError);
  std::filesystem::remove(mesh_path);
  std::filesystem::remove(cloud_path);
}

TEST(DistanceColouredCloud, IsRedBeyondTheThreshold) {
  const std::vector<Eigen::Vector3f> points{{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}};
  const std::vector<float> distances{0.0f, 0.05f, 0.1f, 0.5f};
  const std::string path = temporaryPath("map.ply");
  writeDistanceColouredCloud(path, points, distances, 0.1);
  EXPECT_EQ(io::readPlyPoints(path), points);
  std::ifstream file(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  const std::string header_end = "end_header\n";
  ASSERT_TRUE(contains(bytes, "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty float distance\n"));
  const std::size_t body = bytes.find(header_end) + header_end.size();
  const std::size_t stride = 3 * 4 + 3 + 4;
  ASSERT_EQ(bytes.size(), body + points.size() * stride);
  auto colour = [&](std::size_t i) {
    const auto* rgb = reinterpret_cast<const uint8_t*>(bytes.data() + body + i * stride + 12);
    return std::array<int, 3>{rgb[0], rgb[1], rgb[2]};
  };
  EXPECT_LT(colour(0)[0], 100);   // near: blue
  EXPECT_GT(colour(0)[2], 150);
  EXPECT_EQ(colour(2), (std::array<int, 3>{255, 0, 0}));  // at the threshold: red
  EXPECT_EQ(colour(3), (std::array<int, 3>{255, 0, 0}));
  EXPECT_NE(colour(1), (std::array<int, 3>{255, 0, 0}));
  float distance;
  std::memcpy(&distance, bytes.data() + body + 3 * stride + 15, 4);
  EXPECT_EQ(distance, 0.5f);
  EXPECT_THROW(writeDistanceColouredCloud(path, points, {0.1f}, 0.1), std::invalid_argument);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace range_image_mapping::evaluation
