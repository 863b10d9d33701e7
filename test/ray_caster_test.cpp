// Analytic primitives and Embree ray casting against exact (double) answers.
#include "range_image_mapping/simulation/ray_caster.h"
#include "range_image_mapping/simulation/mesh_primitives.h"
#include "mesh_reference.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <thread>

namespace range_image_mapping::simulation {
namespace {

// A few float ulps of the largest coordinate involved: Embree's answer is float.
double floatTolerance(double distance, const Eigen::Vector3f& origin) {
  return 8.0 * std::numeric_limits<float>::epsilon() * (distance + origin.norm() + 1.0);
}

using test::bruteForceDistance;

// Signed volume by the divergence theorem: positive when normals face outward.
double signedVolume(const TriangleMesh& mesh) {
  double volume = 0.0;
  for (const Eigen::Vector3i& t : mesh.triangles)
    volume += mesh.vertices[t[0]].cast<double>().dot(
                  mesh.vertices[t[1]].cast<double>().cross(mesh.vertices[t[2]].cast<double>())) /
              6.0;
  return volume;
}

Eigen::Vector3f randomUnit(std::mt19937& generator) {
  std::normal_distribution<float> normal;
  return Eigen::Vector3f(normal(generator), normal(generator), normal(generator)).normalized();
}

TEST(TriangleMesh, PrimitivesHaveTheirAnalyticAreaVolumeAndOrientation) {
  const TriangleMesh box = makeBox({-1, -2, 0}, {3, 1, 2.5f});
  EXPECT_NEAR(box.area(), 2 * (4 * 3 + 3 * 2.5 + 4 * 2.5), 1e-5);
  EXPECT_NEAR(signedVolume(box), 4 * 3 * 2.5, 1e-5);
  EXPECT_NEAR(signedVolume(makeBox({-1, -2, 0}, {3, 1, 2.5f}, true)), -4 * 3 * 2.5, 1e-5);
  EXPECT_TRUE(box.bounds().isApprox(Eigen::AlignedBox3f(Eigen::Vector3f(-1, -2, 0), Eigen::Vector3f(3, 1, 2.5f))));

  const float radius = 2.0f;
  const TriangleMesh sphere = makeSphere({1, 2, 3}, radius, 4);
  EXPECT_EQ(sphere.triangles.size(), 20u * 256u);
  for (const Eigen::Vector3f& vertex : sphere.vertices)
    EXPECT_NEAR((vertex - Eigen::Vector3f(1, 2, 3)).norm(), radius, 1e-6);
  // Inscribed: slightly below the sphere's area and volume, converging to it.
  const double area = 4 * M_PI * radius * radius;
  EXPECT_LT(sphere.area(), area);
  EXPECT_GT(sphere.area(), 0.995 * area);
  EXPECT_GT(signedVolume(makeSphere({0, 0, 0}, radius, 4)), 0.99 * 4.0 / 3.0 * M_PI * 8.0);

  const TriangleMesh cylinder = makeCylinder({0, 0, 0}, 0.5f, 3.0f, 64);
  const double polygon = 0.5 * 64 * 0.25 * std::sin(2 * M_PI / 64);  // each cap
  const double perimeter = 64 * 2 * 0.5 * std::sin(M_PI / 64);
  EXPECT_NEAR(cylinder.area(), 2 * polygon + perimeter * 3.0, 1e-4);
  EXPECT_NEAR(signedVolume(cylinder), polygon * 3.0, 1e-4);

  const TriangleMesh quad = makeQuad({0, 0, 1}, {2, 0, 0}, {0, 3, 0});
  EXPECT_NEAR(quad.area(), 6.0, 1e-6);

  TriangleMesh scene = quad;
  Eigen::Isometry3f shift = Eigen::Isometry3f::Identity();
  shift.translation() = Eigen::Vector3f(10, 0, 0);
  scene.append(box, shift);
  EXPECT_EQ(scene.triangles.size(), 14u);
  EXPECT_EQ(scene.vertices.size(), 12u);
  EXPECT_FLOAT_EQ(scene.bounds().max().x(), 13.0f);
  EXPECT_NEAR(scene.area(), quad.area() + box.area(), 1e-4);
}

TEST(TriangleMesh, RejectsDegenerateParameters) {
  EXPECT_THROW(makeBox({0, 0, 0}, {1, 0, 1}), std::invalid_argument);
  EXPECT_THROW(makeSphere({0, 0, 0}, -1.0f), std::invalid_argument);
  EXPECT_THROW(makeSphere({0, 0, 0}, 1.0f, 9), std::invalid_argument);
  EXPECT_THROW(makeCylinder({0, 0, 0}, 1.0f, 1.0f, 2), std::invalid_argument);
  EXPECT_THROW(makeQuad({0, 0, 0}, {1, 0, 0}, {2, 0, 0}), std::invalid_argument);
  EXPECT_THROW(makeQuad({0, NAN, 0}, {1, 0, 0}, {0, 1, 0}), std::invalid_argument);
}

TEST(RayCaster, PlaneDistancesAreExactToFloatPrecision) {
  const float height = 7.25f;
  const RayCaster caster(makeQuad({-500, -500, height}, {1000, 0, 0}, {0, 1000, 0}));
  std::mt19937 generator(3);
  std::uniform_real_distribution<float> coordinate(-20.0f, 20.0f);
  std::vector<Eigen::Vector3f> origins, directions;
  for (int i = 0; i < 5000; ++i) {
    origins.emplace_back(coordinate(generator), coordinate(generator), 0.5f * coordinate(generator) / 20.0f);
    Eigen::Vector3f direction = randomUnit(generator);
    direction.z() = std::abs(direction.z()) + 0.05f;  // upward, toward the plane
    directions.push_back(direction.normalized());
  }
  std::vector<float> distances(origins.size());
  std::vector<Eigen::Vector3f> normals(origins.size());
  caster.cast(origins.data(), directions.data(), origins.size(), 0.0f, 1e4f, distances.data(),
              normals.data());
  for (std::size_t i = 0; i < origins.size(); ++i) {
    const double expected = (height - double(origins[i].z())) / double(directions[i].z());
    if (std::abs(origins[i].x() + expected * directions[i].x()) > 499 ||
        std::abs(origins[i].y() + expected * directions[i].y()) > 499)
      continue;  // past the quad's border
    ASSERT_NEAR(distances[i], expected, floatTolerance(expected, origins[i])) << "ray " << i;
    // Counter-clockwise seen from above: the normal faces +z.
    EXPECT_NEAR(normals[i].z(), 1.0f, 1e-6f);
  }
}

TEST(RayCaster, MissesNearAndFarGiveNaN) {
  const RayCaster caster(makeQuad({-1, -1, 5}, {2, 0, 0}, {0, 2, 0}));
  const Eigen::Vector3f origin(0, 0, 0);
  EXPECT_NEAR(caster.castOne(origin, Eigen::Vector3f::UnitZ(), 0.0f, 100.0f), 5.0f, 1e-6f);
  EXPECT_TRUE(std::isnan(caster.castOne(origin, -Eigen::Vector3f::UnitZ(), 0.0f, 100.0f)));
  EXPECT_TRUE(std::isnan(caster.castOne(origin, Eigen::Vector3f::UnitX(), 0.0f, 100.0f)));
  EXPECT_TRUE(std::isnan(caster.castOne(origin, Eigen::Vector3f::UnitZ(), 0.0f, 4.9f)));   // too far
  EXPECT_TRUE(std::isnan(caster.castOne(origin, Eigen::Vector3f::UnitZ(), 5.1f, 100.0f)));  // too near
  Eigen::Vector3f normal;
  caster.castOne(origin, -Eigen::Vector3f::UnitZ(), 0.0f, 100.0f, &normal);
  EXPECT_EQ(normal, Eigen::Vector3f::Zero());
  const RayCaster empty{TriangleMesh{}};
  EXPECT_TRUE(std::isnan(empty.castOne(origin, Eigen::Vector3f::UnitZ(), 0.0f, 100.0f)));
}

TEST(RayCaster, ClosedRoomHasNoLeaksThroughEdgesAndCorners) {
  const Eigen::Vector3f minimum(-3, -4, -1.5f), maximum(5, 2, 2.5f);
  const RayCaster caster(makeBox(minimum, maximum, true));
  std::mt19937 generator(7);
  std::vector<Eigen::Vector3f> directions;
  for (int i = 0; i < 20000; ++i) directions.push_back(randomUnit(generator));
  // Rays aimed exactly at the corners and along the diagonals of the walls.
  const Eigen::Vector3f origin(0, 0, 0);
  for (int corner = 0; corner < 8; ++corner)
    directions.push_back(Eigen::Vector3f((corner & 1) ? maximum.x() : minimum.x(),
                                         (corner & 2) ? maximum.y() : minimum.y(),
                                         (corner & 4) ? maximum.z() : minimum.z())
                             .normalized());
  const std::vector<Eigen::Vector3f> origins(directions.size(), origin);
  std::vector<float> distances(directions.size());
  std::vector<Eigen::Vector3f> normals(directions.size());
  caster.cast(origins.data(), directions.data(), directions.size(), 0.0f, 100.0f, distances.data(),
              normals.data());
  for (std::size_t i = 0; i < directions.size(); ++i) {
    double expected = std::numeric_limits<double>::infinity();
    for (int axis = 0; axis < 3; ++axis) {
      const double d = directions[i][axis];
      if (d > 0) expected = std::min(expected, maximum[axis] / d);
      if (d < 0) expected = std::min(expected, minimum[axis] / d);
    }
    ASSERT_FALSE(std::isnan(distances[i])) << "ray " << i << " left the room";
    ASSERT_NEAR(distances[i], expected, floatTolerance(expected, origin)) << "ray " << i;
    // Inward-facing walls: the normal faces the sensor.
    EXPECT_LT(normals[i].dot(directions[i]), 0.0f);
  }
}

TEST(RayCaster, SphereDistancesMatchBruteForceInDouble) {
  const TriangleMesh sphere = makeSphere({10, 1, -0.5f}, 3.0f, 3);
  const RayCaster caster(sphere);
  std::mt19937 generator(11);
  std::uniform_real_distribution<float> spread(-0.35f, 0.35f);
  int hits = 0;
  for (int i = 0; i < 1500; ++i) {
    const Eigen::Vector3f origin(0.1f * spread(generator), 0.1f * spread(generator), 0);
    const Eigen::Vector3f direction =
        Eigen::Vector3f(1.0f, 0.1f + spread(generator), -0.05f + spread(generator)).normalized();
    const float distance = caster.castOne(origin, direction, 0.0f, 100.0f);
    const double expected = bruteForceDistance(sphere, origin.cast<double>(), direction.cast<double>());
    ASSERT_EQ(std::isnan(distance), std::isnan(expected)) << "ray " << i;
    if (std::isnan(expected)) continue;
    ++hits;
    ASSERT_NEAR(distance, expected, floatTolerance(expected, origin)) << "ray " << i;
  }
  EXPECT_GT(hits, 500);
}

TEST(RayCaster, BatchedAndConcurrentQueriesAgreeWithSingleRays) {
  TriangleMesh scene = makeBox({-30, -30, -2}, {30, 30, 10}, true);
  for (int i = 0; i < 20; ++i)
    scene.append(makeCylinder({-20.0f + 2.0f * i, 5.0f * std::sin(float(i)), -2.0f}, 0.3f, 4.0f));
  scene.append(makeSphere({4, -6, 1}, 2.0f, 3));
  const RayCaster caster(scene);
  std::mt19937 generator(5);
  std::vector<Eigen::Vector3f> directions;
  for (int i = 0; i < 4096; ++i) directions.push_back(randomUnit(generator));
  const std::vector<Eigen::Vector3f> origins(directions.size(), Eigen::Vector3f(0.5f, 0.2f, 1.0f));
  std::vector<float> single(directions.size());
  for (std::size_t i = 0; i < directions.size(); ++i)
    single[i] = caster.castOne(origins[i], directions[i], 0.0f, 1000.0f);
  std::vector<std::vector<float>> batched(4, std::vector<float>(directions.size()));
  std::vector<std::thread> threads;
  for (auto& result : batched)
    threads.emplace_back([&] {
      for (int repeat = 0; repeat < 5; ++repeat)
        caster.cast(origins.data(), directions.data(), directions.size(), 0.0f, 1000.0f, result.data());
    });
  for (std::thread& thread : threads) thread.join();
  for (const auto& result : batched)
    for (std::size_t i = 0; i < directions.size(); ++i) {
      ASSERT_FALSE(std::isnan(result[i])) << "ray " << i;
      ASSERT_NEAR(result[i], single[i], floatTolerance(single[i], origins[i])) << "ray " << i;
    }
}

TEST(RayCaster, RejectsBadMeshesNamingTheProblem) {
  TriangleMesh mesh = makeQuad({0, 0, 0}, {1, 0, 0}, {0, 1, 0});
  mesh.triangles.emplace_back(0, 1, 4);
  try {
    RayCaster caster(mesh);
    FAIL() << "expected an error";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("triangle 2 has vertex index 4"), std::string::npos)
        << error.what();
  }
  mesh = makeQuad({0, 0, 0}, {1, 0, 0}, {0, 1, 0});
  mesh.vertices[2].y() = std::numeric_limits<float>::infinity();
  EXPECT_THROW(RayCaster{mesh}, std::invalid_argument);
}

}  // namespace
}  // namespace range_image_mapping::simulation
