#include "range_image_mapping/simulation/scene_generator.h"
#include "range_image_mapping/simulation/mesh_primitives.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <optional>
#include <tuple>

namespace range_image_mapping::simulation {
namespace {

using Eigen::Vector3d;

// ---------------------------------------------------------------- scenes, generated once

const Scene& cachedScene(SceneKind kind, uint32_t seed, double extent_m = 0.0) {
  static std::map<std::tuple<int, uint32_t, double>, Scene> scenes;
  const auto key = std::make_tuple(static_cast<int>(kind), seed, extent_m);
  auto found = scenes.find(key);
  if (found == scenes.end()) {
    SceneOptions options;
    options.kind = kind;
    options.seed = seed;
    options.extent_m = extent_m;
    const auto start = std::chrono::steady_clock::now();
    Scene scene = generateScene(options);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::cout << (kind == SceneKind::kIndoor ? "indoor" : "outdoor") << " seed " << seed
              << " extent " << extent_m << ": " << scene.mesh.triangles.size() << " triangles, "
              << scene.mesh.vertices.size() << " vertices, route " << scene.route.size()
              << " points, generated in " << seconds << " s\n";
    found = scenes.emplace(key, std::move(scene)).first;
  }
  return found->second;
}

// ---------------------------------------------------------------- exact geometry (Ericson,
// Real-Time Collision Detection, 5.1.5 and 5.1.9), independent of the generator

struct Triangle {
  Vector3d a, b, c;
};

Triangle triangleOf(const TriangleMesh& mesh, std::size_t index) {
  const Eigen::Vector3i& t = mesh.triangles[index];
  return {mesh.vertices[t[0]].cast<double>(), mesh.vertices[t[1]].cast<double>(),
          mesh.vertices[t[2]].cast<double>()};
}

Vector3d closestOnTriangle(const Vector3d& p, const Triangle& t) {
  const Vector3d ab = t.b - t.a, ac = t.c - t.a, ap = p - t.a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return t.a;
  const Vector3d bp = p - t.b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return t.b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return t.a + d1 / (d1 - d3) * ab;
  const Vector3d cp = p - t.c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return t.c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return t.a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
    return t.b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (t.c - t.b);
  const double denominator = 1.0 / (va + vb + vc);
  return t.a + ab * (vb * denominator) + ac * (vc * denominator);
}

double segmentSegmentDistance(const Vector3d& p1, const Vector3d& q1, const Vector3d& p2,
                              const Vector3d& q2) {
  const Vector3d d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  double s = 0, t = 0;
  if (a <= 1e-18 && e <= 1e-18) return r.norm();
  if (a <= 1e-18) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= 1e-18) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2), denominator = a * e - b * b;
      s = denominator > 1e-18 ? std::clamp((b * f - c * e) / denominator, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0) {
        t = 0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1) {
        t = 1;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  return ((p1 + d1 * s) - (p2 + d2 * t)).norm();
}

bool segmentCrossesTriangle(const Vector3d& p, const Vector3d& q, const Triangle& t) {
  const Vector3d direction = q - p, e1 = t.b - t.a, e2 = t.c - t.a;
  const Vector3d h = direction.cross(e2);
  const double det = e1.dot(h);
  if (std::abs(det) < 1e-15) return false;  // parallel: the edge distances cover it
  const Vector3d s = p - t.a;
  const double u = s.dot(h) / det;
  const Vector3d qv = s.cross(e1);
  const double v = direction.dot(qv) / det, along = e2.dot(qv) / det;
  return u >= 0 && v >= 0 && u + v <= 1 && along >= 0 && along <= 1;
}

double triangleDistance(const Triangle& x, const Triangle& y) {
  const Vector3d xs[3] = {x.a, x.b, x.c}, ys[3] = {y.a, y.b, y.c};
  for (int i = 0; i < 3; ++i)
    if (segmentCrossesTriangle(xs[i], xs[(i + 1) % 3], y) ||
        segmentCrossesTriangle(ys[i], ys[(i + 1) % 3], x))
      return 0.0;
  double best = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 3; ++i) {
    best = std::min(best, (closestOnTriangle(xs[i], y) - xs[i]).norm());
    best = std::min(best, (closestOnTriangle(ys[i], x) - ys[i]).norm());
    for (int j = 0; j < 3; ++j)
      best = std::min(best, segmentSegmentDistance(xs[i], xs[(i + 1) % 3], ys[j], ys[(j + 1) % 3]));
  }
  return best;
}

Eigen::AlignedBox3d boundsOf(const Triangle& t) {
  Eigen::AlignedBox3d box(t.a);
  box.extend(t.b);
  box.extend(t.c);
  return box;
}

// Smallest distance from any triangle that is not ground to the band the
// scene promises to keep free (lowest..highest above each route segment);
// distances beyond the promised clearance are reported as the clearance.
double smallestClearance(const Scene& scene, std::size_t* nearest_triangle = nullptr) {
  const RouteClearance& clearance = scene.route_clearance;
  std::vector<Triangle> band;
  std::vector<Eigen::AlignedBox3d> band_bounds;
  for (std::size_t i = 0; i + 1 < scene.route.size(); ++i) {
    const Vector3d low_from = scene.route[i] + Vector3d(0, 0, clearance.lowest_m);
    const Vector3d low_to = scene.route[i + 1] + Vector3d(0, 0, clearance.lowest_m);
    const Vector3d up(0, 0, clearance.highest_m - clearance.lowest_m);
    band.push_back({low_from, low_to, low_to + up});
    band.push_back({low_from, low_to + up, low_from + up});
    band_bounds.push_back(boundsOf(band[band.size() - 2]).extend(boundsOf(band.back())));
    band_bounds.push_back(band_bounds.back());
  }
  double smallest = clearance.distance_m;
  for (std::size_t index = 0; index < scene.mesh.triangles.size(); ++index) {
    if (scene.triangle_classes[index] == SurfaceClass::kGround) continue;
    const Triangle triangle = triangleOf(scene.mesh, index);
    const Eigen::AlignedBox3d bounds = boundsOf(triangle);
    for (std::size_t b = 0; b < band.size(); ++b) {
      const Vector3d gap = (band_bounds[b].min() - bounds.max())
                               .cwiseMax(bounds.min() - band_bounds[b].max())
                               .cwiseMax(0.0);
      if (gap.norm() >= smallest) continue;
      const double distance = triangleDistance(triangle, band[b]);
      if (distance < smallest) {
        smallest = distance;
        if (nearest_triangle) *nearest_triangle = index;
      }
    }
  }
  return smallest;
}

struct VerticalHit {
  double z;
  SurfaceClass surface;
};

// The nearest triangle straight above (up) or below a point, by brute force.
std::optional<VerticalHit> verticalHit(const Scene& scene, const Vector3d& point, bool up) {
  std::optional<VerticalHit> best;
  for (std::size_t index = 0; index < scene.mesh.triangles.size(); ++index) {
    const Triangle t = triangleOf(scene.mesh, index);
    const Eigen::Vector2d p = point.head<2>(), a = t.a.head<2>(), b = t.b.head<2>(),
                          c = t.c.head<2>();
    const double area = (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
    if (std::abs(area) < 1e-12) continue;  // vertical
    const double wb = ((p - a).x() * (c - a).y() - (p - a).y() * (c - a).x()) / area;
    const double wc = ((b - a).x() * (p - a).y() - (b - a).y() * (p - a).x()) / area;
    if (wb < 0 || wc < 0 || wb + wc > 1) continue;
    const double z = t.a.z() + wb * (t.b.z() - t.a.z()) + wc * (t.c.z() - t.a.z());
    if (up ? z < point.z() : z > point.z()) continue;
    if (!best || std::abs(z - point.z()) < std::abs(best->z - point.z()))
      best = VerticalHit{z, scene.triangle_classes[index]};
  }
  return best;
}

// Distance along a horizontal ray to the first triangle, or infinity.
double horizontalHit(const Scene& scene, const Vector3d& origin, const Vector3d& direction) {
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t index = 0; index < scene.mesh.triangles.size(); ++index) {
    const Triangle t = triangleOf(scene.mesh, index);
    const Vector3d e1 = t.b - t.a, e2 = t.c - t.a, h = direction.cross(e2);
    const double det = e1.dot(h);
    if (std::abs(det) < 1e-12) continue;
    const Vector3d s = origin - t.a, q = s.cross(e1);
    const double u = s.dot(h) / det, v = direction.dot(q) / det, distance = e2.dot(q) / det;
    if (u >= 0 && v >= 0 && u + v <= 1 && distance > 0) best = std::min(best, distance);
  }
  return best;
}

// Sum of the absolute turning angles along the closed route.
double totalTurning(const std::vector<Vector3d>& route) {
  double total = 0.0;
  const std::size_t count = route.size() - 1;  // the last point repeats the first
  for (std::size_t i = 0; i < count; ++i) {
    const Eigen::Vector2d in = (route[i] - route[(i + count - 1) % count]).head<2>();
    const Eigen::Vector2d out = (route[(i + 1) % count] - route[i]).head<2>();
    total += std::abs(std::atan2(in.x() * out.y() - in.y() * out.x(), in.dot(out)));
  }
  return total;
}

void expectClosedRouteWithinBounds(const Scene& scene, double extent_m) {
  ASSERT_GE(scene.route.size(), 8u);
  EXPECT_EQ(scene.route.front(), scene.route.back());
  double longest_step = 0.0;
  for (std::size_t i = 0; i + 1 < scene.route.size(); ++i) {
    longest_step = std::max(longest_step, (scene.route[i + 1] - scene.route[i]).norm());
    EXPECT_GT((scene.route[i + 1] - scene.route[i]).norm(), 1e-3) << "repeated point " << i;
  }
  for (const Vector3d& point : scene.route) {
    ASSERT_TRUE(point.allFinite());
    EXPECT_LT(point.head<2>().cwiseAbs().maxCoeff(), extent_m / 2.0) << point.transpose();
  }
  // Turning stays below a U-turn at every point (corners are rounded arcs).
  const std::size_t count = scene.route.size() - 1;
  for (std::size_t i = 0; i < count; ++i) {
    const Eigen::Vector2d in = (scene.route[i] - scene.route[(i + count - 1) % count]).head<2>();
    const Eigen::Vector2d out = (scene.route[(i + 1) % count] - scene.route[i]).head<2>();
    EXPECT_LT(std::abs(std::atan2(in.x() * out.y() - in.y() * out.x(), in.dot(out))), 0.2)
        << "point " << i;
  }
}

// ---------------------------------------------------------------- tests

TEST(SceneGenerator, SameSeedGivesTheSameBytesOtherSeedsDiffer) {
  for (const SceneKind kind : {SceneKind::kIndoor, SceneKind::kOutdoor}) {
    SceneOptions options;
    options.kind = kind;
    options.seed = 7;
    const Scene first = generateScene(options);
    const Scene& second = cachedScene(kind, 7);
    ASSERT_EQ(first.mesh.vertices.size(), second.mesh.vertices.size());
    ASSERT_EQ(first.mesh.triangles.size(), second.mesh.triangles.size());
    EXPECT_EQ(std::memcmp(first.mesh.vertices.data(), second.mesh.vertices.data(),
                          first.mesh.vertices.size() * sizeof(Eigen::Vector3f)),
              0);
    EXPECT_EQ(std::memcmp(first.mesh.triangles.data(), second.mesh.triangles.data(),
                          first.mesh.triangles.size() * sizeof(Eigen::Vector3i)),
              0);
    EXPECT_EQ(first.triangle_classes, second.triangle_classes);
    EXPECT_EQ(first.route, second.route);

    const Scene& other = cachedScene(kind, 8);
    EXPECT_TRUE(other.mesh.vertices.size() != first.mesh.vertices.size() ||
                std::memcmp(other.mesh.vertices.data(), first.mesh.vertices.data(),
                            first.mesh.vertices.size() * sizeof(Eigen::Vector3f)) != 0);
    EXPECT_NE(other.route, first.route);
  }
}

TEST(SceneGenerator, EveryTriangleHasAClassAndValidCorners) {
  for (const SceneKind kind : {SceneKind::kIndoor, SceneKind::kOutdoor}) {
    const Scene& scene = cachedScene(kind, 7);
    ASSERT_EQ(scene.triangle_classes.size(), scene.mesh.triangles.size());
    const int vertex_count = static_cast<int>(scene.mesh.vertices.size());
    for (const Eigen::Vector3i& triangle : scene.mesh.triangles)
      ASSERT_TRUE((triangle.array() >= 0).all() && (triangle.array() < vertex_count).all());
    for (const Eigen::Vector3f& vertex : scene.mesh.vertices) ASSERT_TRUE(vertex.allFinite());
    for (const SurfaceClass surface : scene.triangle_classes)
      ASSERT_LE(static_cast<int>(surface), static_cast<int>(SurfaceClass::kVegetation));
  }
}

TEST(SceneGenerator, IndoorRouteIsClosedEnclosedAndVisitsRooms) {
  for (const uint32_t seed : {7u, 8u}) {
    const Scene& scene = cachedScene(SceneKind::kIndoor, seed);
    expectClosedRouteWithinBounds(scene, 40.0);
    // A plain ring turns 360 degrees; each detour through a room adds 360 more.
    EXPECT_GE(totalTurning(scene.route), 4.0 * M_PI - 0.1) << "seed " << seed;
    for (std::size_t i = 0; i < scene.route.size(); i += 4) {
      const Vector3d sensor = scene.route[i] + Vector3d(0, 0, 1.0);
      const std::optional<VerticalHit> floor = verticalHit(scene, sensor, false);
      ASSERT_TRUE(floor) << "no floor under route point " << i;
      EXPECT_EQ(floor->surface, SurfaceClass::kGround);
      EXPECT_NEAR(floor->z, scene.route[i].z(), 1e-6);
      const std::optional<VerticalHit> ceiling = verticalHit(scene, sensor, true);
      ASSERT_TRUE(ceiling) << "open above route point " << i;
      EXPECT_GE(ceiling->z - floor->z,
                2.68);  // a ceiling light hangs 6 cm below a 2.75-3 m ceiling
      EXPECT_LE(ceiling->z - floor->z, 3.0);
      // Walls all around: every horizontal ray ends inside the building.
      for (int k = 0; k < 8; ++k) {
        const Vector3d direction(std::cos(k * M_PI / 4 + 0.1), std::sin(k * M_PI / 4 + 0.1), 0.0);
        EXPECT_LT(horizontalHit(scene, sensor, direction), 40.0 * std::sqrt(2.0))
            << "route point " << i;
      }
    }
  }
}

TEST(SceneGenerator, OutdoorRouteIsClosedOnTheRoadWithinBounds) {
  for (const uint32_t seed : {7u, 8u}) {
    const Scene& scene = cachedScene(SceneKind::kOutdoor, seed);
    expectClosedRouteWithinBounds(scene, 300.0);
    EXPECT_GE(totalTurning(scene.route), 2.0 * M_PI - 0.1);
    double length = 0.0;
    for (std::size_t i = 0; i + 1 < scene.route.size(); ++i)
      length += (scene.route[i + 1] - scene.route[i]).norm();
    EXPECT_GT(length, 150.0);
    // The route lies on the road: the ground right below, within the mesh's rounding.
    for (std::size_t i = 0; i < scene.route.size(); i += 3) {
      const std::optional<VerticalHit> ground =
          verticalHit(scene, scene.route[i] + Vector3d(0, 0, 1.0), false);
      ASSERT_TRUE(ground) << "no ground under route point " << i;
      EXPECT_EQ(ground->surface, SurfaceClass::kGround);
      EXPECT_NEAR(ground->z, scene.route[i].z(), 0.01) << "route point " << i;
      EXPECT_FALSE(verticalHit(scene, scene.route[i] + Vector3d(0, 0, 0.5), true))
          << "covered at route point " << i;
    }
  }
}

TEST(SceneGenerator, RouteKeepsItsClearance) {
  const std::tuple<SceneKind, uint32_t, double> cases[] = {
      {SceneKind::kIndoor, 7, 0.0},   {SceneKind::kIndoor, 8, 0.0},  {SceneKind::kIndoor, 3, 20.0},
      {SceneKind::kIndoor, 4, 90.0},  {SceneKind::kOutdoor, 7, 0.0}, {SceneKind::kOutdoor, 8, 0.0},
      {SceneKind::kOutdoor, 5, 120.0}};
  for (const auto& [kind, seed, extent] : cases) {
    const Scene& scene = cachedScene(kind, seed, extent);
    const RouteClearance& clearance = scene.route_clearance;
    EXPECT_GE(clearance.distance_m, kind == SceneKind::kIndoor ? 0.6 : 1.5);
    EXPECT_LE(clearance.lowest_m, kind == SceneKind::kIndoor ? 0.5 : 1.0);
    EXPECT_GE(clearance.highest_m, kind == SceneKind::kIndoor ? 1.9 : 3.0);
    std::size_t nearest = 0;
    const double smallest = smallestClearance(scene, &nearest);
    // Vertices are floats: allow their rounding.
    EXPECT_GE(smallest, clearance.distance_m - 1e-4)
        << "seed " << seed << " extent " << extent << ": triangle " << nearest << " of class "
        << int(scene.triangle_classes[nearest]) << " is " << smallest << " m from the route";
  }
}

TEST(SceneGenerator, ClearanceCheckFindsAnObstacleOnTheRoute) {
  Scene scene = cachedScene(SceneKind::kIndoor, 7);
  const Vector3d middle = 0.5 * (scene.route[5] + scene.route[6]) + Vector3d(0, 0, 2.2);
  // A pipe hanging 0.3 m above the band: closer than the clearance.
  scene.mesh.append(makeBox((middle - Vector3d(0.5, 0.5, 0.05)).cast<float>(),
                            (middle + Vector3d(0.5, 0.5, 0.05)).cast<float>()));
  scene.triangle_classes.resize(scene.mesh.triangles.size(), SurfaceClass::kPole);
  EXPECT_NEAR(smallestClearance(scene), 2.2 - 0.05 - scene.route_clearance.highest_m, 1e-3);
}

TEST(SceneGenerator, OutdoorGroundIsGentleWithKerbSteps) {
  const Scene& scene = cachedScene(SceneKind::kOutdoor, 7);
  std::size_t ground_triangles = 0, kerb_triangles = 0;
  double steepest = 0.0;
  Eigen::AlignedBox3d ground_bounds;
  for (std::size_t index = 0; index < scene.mesh.triangles.size(); ++index) {
    if (scene.triangle_classes[index] != SurfaceClass::kGround) continue;
    const Triangle t = triangleOf(scene.mesh, index);
    ground_bounds.extend(boundsOf(t));
    const Vector3d normal = (t.b - t.a).cross(t.c - t.a).normalized();
    if (std::abs(normal.z()) > 1e-3) {
      ++ground_triangles;
      EXPECT_GT(normal.z(), 0.0) << "ground triangle " << index << " faces down";
      steepest = std::max(steepest, normal.head<2>().norm() / normal.z());
    } else {
      ++kerb_triangles;
      EXPECT_LE(boundsOf(t).sizes().z(), 0.2)
          << "vertical ground triangle " << index << " is not a kerb";
    }
  }
  EXPECT_GT(ground_triangles, 1000u);
  EXPECT_GT(kerb_triangles, 100u);
  EXPECT_LE(steepest, 0.04);
  EXPECT_GT(steepest, 0.005);  // not flat either
  // The ground covers the whole scene.
  EXPECT_NEAR(ground_bounds.min().x(), -150.0, 1e-3);
  EXPECT_NEAR(ground_bounds.max().y(), 150.0, 1e-3);
}

TEST(SceneGenerator, OutdoorHasBuildingsCarsTreesPolesAndFits) {
  for (const uint32_t seed : {7u, 8u}) {
    const Scene& scene = cachedScene(SceneKind::kOutdoor, seed);
    std::map<SurfaceClass, std::size_t> counts;
    for (const SurfaceClass surface : scene.triangle_classes) ++counts[surface];
    for (const SurfaceClass surface :
         {SurfaceClass::kGround, SurfaceClass::kBuilding, SurfaceClass::kFurniture,
          SurfaceClass::kPole, SurfaceClass::kVehicle, SurfaceClass::kVegetation})
      EXPECT_GT(counts[surface], 500u) << "class " << int(surface);
    EXPECT_LE(scene.mesh.triangles.size(), 1500000u);
    // Buildings from 6 to 30 m (plus parapet and roof plant), on a ground within a few metres of 0.
    Eigen::AlignedBox3d buildings;
    for (std::size_t index = 0; index < scene.mesh.triangles.size(); ++index)
      if (scene.triangle_classes[index] == SurfaceClass::kBuilding)
        buildings.extend(boundsOf(triangleOf(scene.mesh, index)));
    EXPECT_GT(buildings.max().z(), 15.0);
    EXPECT_LT(buildings.max().z(), 30.0 + 1.1 + 2.5 + 4.0);
  }
}

TEST(SceneGenerator, IndoorHasStairsThinPolesAndFurniture) {
  for (const uint32_t seed : {7u, 8u}) {
    const Scene& scene = cachedScene(SceneKind::kIndoor, seed);
    std::size_t step_tops = 0, furniture = 0;
    double thinnest_pole = 1.0;
    for (std::size_t index = 0; index < scene.mesh.triangles.size(); ++index) {
      const Triangle t = triangleOf(scene.mesh, index);
      const Vector3d normal = (t.b - t.a).cross(t.c - t.a).normalized();
      const SurfaceClass surface = scene.triangle_classes[index];
      // Treads: upward faces of the building between floor and head height.
      if (surface == SurfaceClass::kBuilding && normal.z() > 0.99 && t.a.z() > 0.1 && t.a.z() < 2.0)
        ++step_tops;
      if (surface == SurfaceClass::kFurniture) ++furniture;
      if (surface == SurfaceClass::kPole && boundsOf(t).sizes().z() > 1.0)
        thinnest_pole = std::min(thinnest_pole, boundsOf(t).sizes().head<2>().norm());
    }
    EXPECT_GE(step_tops, 2u * 7u) << "seed " << seed << ": no stair flight";
    EXPECT_GT(furniture, 1000u);
    // A side of a 12-gon of radius 0.025 m is under 0.015 m wide.
    EXPECT_LT(thinnest_pole, 0.02) << "seed " << seed << ": no thin pole";
  }
}

TEST(SceneGenerator, RejectsExtentsOutsideTheRange) {
  const auto message = [](SceneKind kind, double extent) -> std::string {
    SceneOptions options;
    options.kind = kind;
    options.extent_m = extent;
    try {
      generateScene(options);
    } catch (const std::invalid_argument& error) {
      return error.what();
    }
    return "no invalid_argument";
  };
  EXPECT_NE(message(SceneKind::kIndoor, 19.0)
                .find("indoor extent_m must be 0 (default 40 m) or within [20, 150] m, got 19"),
            std::string::npos);
  EXPECT_NE(message(SceneKind::kOutdoor, 5000.0).find("outdoor extent_m must be"),
            std::string::npos);
  EXPECT_NE(message(SceneKind::kOutdoor, -300.0).find("got -300"), std::string::npos);
  EXPECT_NE(message(SceneKind::kIndoor, std::nan("")).find("got nan"), std::string::npos);
  EXPECT_NE(message(static_cast<SceneKind>(7), 0.0).find("unknown scene kind 7"),
            std::string::npos);
}

}  // namespace
}  // namespace range_image_mapping::simulation
