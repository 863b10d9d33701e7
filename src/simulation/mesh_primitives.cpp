#include "range_image_mapping/simulation/mesh_primitives.h"

#include <cmath>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>

namespace range_image_mapping::simulation {
namespace {

void requireFinite(const Eigen::Vector3f& value, const char* what) {
  if (!value.allFinite()) throw std::invalid_argument(std::string(what) + " is not finite");
}

void requirePositive(float value, const char* what) {
  if (!(std::isfinite(value) && value > 0.0f))
    throw std::invalid_argument(std::string(what) + " must be positive and finite, got " +
                                std::to_string(value));
}

// Icosahedron faces split into four, new vertices pushed onto the unit sphere;
// a shared edge's midpoint is made once so the mesh stays watertight.
class UnitIcosphere {
 public:
  explicit UnitIcosphere(int subdivisions) {
    const double golden = (1.0 + std::sqrt(5.0)) / 2.0;
    const double corners[12][3] = {{-1, golden, 0}, {1, golden, 0}, {-1, -golden, 0}, {1, -golden, 0},
                                   {0, -1, golden}, {0, 1, golden}, {0, -1, -golden}, {0, 1, -golden},
                                   {golden, 0, -1}, {golden, 0, 1}, {-golden, 0, -1}, {-golden, 0, 1}};
    for (const auto& corner : corners)
      vertices_.push_back(Eigen::Vector3d(corner[0], corner[1], corner[2]).normalized());
    triangles_ = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                  {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                  {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                  {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
    for (int level = 0; level < subdivisions; ++level) subdivide();
  }
  const std::vector<Eigen::Vector3d>& vertices() const { return vertices_; }
  const std::vector<Eigen::Vector3i>& triangles() const { return triangles_; }

 private:
  int midpoint(int a, int b) {
    const auto key = std::minmax(a, b);
    const auto found = midpoints_.find(key);
    if (found != midpoints_.end()) return found->second;
    vertices_.push_back((vertices_[a] + vertices_[b]).normalized());
    const int index = static_cast<int>(vertices_.size()) - 1;
    midpoints_.emplace(key, index);
    return index;
  }
  void subdivide() {
    std::vector<Eigen::Vector3i> finer;
    finer.reserve(triangles_.size() * 4);
    midpoints_.clear();
    for (const Eigen::Vector3i& t : triangles_) {
      const int ab = midpoint(t[0], t[1]), bc = midpoint(t[1], t[2]), ca = midpoint(t[2], t[0]);
      finer.emplace_back(t[0], ab, ca);
      finer.emplace_back(t[1], bc, ab);
      finer.emplace_back(t[2], ca, bc);
      finer.emplace_back(ab, bc, ca);
    }
    triangles_ = std::move(finer);
  }

  std::vector<Eigen::Vector3d> vertices_;
  std::vector<Eigen::Vector3i> triangles_;
  std::map<std::pair<int, int>, int> midpoints_;
};

}  // namespace

TriangleMesh makeQuad(const Eigen::Vector3f& corner, const Eigen::Vector3f& edge_u,
                      const Eigen::Vector3f& edge_v) {
  requireFinite(corner, "makeQuad: corner");
  requireFinite(edge_u, "makeQuad: edge_u");
  requireFinite(edge_v, "makeQuad: edge_v");
  if (!(edge_u.cross(edge_v).norm() > 0.0f))
    throw std::invalid_argument("makeQuad: edge_u and edge_v are parallel or zero");
  TriangleMesh quad;
  quad.vertices = {corner, corner + edge_u, corner + edge_u + edge_v, corner + edge_v};
  quad.triangles = {{0, 1, 2}, {0, 2, 3}};
  return quad;
}

TriangleMesh makeBox(const Eigen::Vector3f& minimum, const Eigen::Vector3f& maximum,
                     bool inward_facing) {
  requireFinite(minimum, "makeBox: minimum");
  requireFinite(maximum, "makeBox: maximum");
  if (!(minimum.array() < maximum.array()).all())
    throw std::invalid_argument("makeBox: minimum must be below maximum on every axis");
  TriangleMesh box;
  // Corner i has x from bit 0, y from bit 1, z from bit 2.
  for (int i = 0; i < 8; ++i)
    box.vertices.emplace_back((i & 1) ? maximum.x() : minimum.x(), (i & 2) ? maximum.y() : minimum.y(),
                              (i & 4) ? maximum.z() : minimum.z());
  // Two triangles per face, counter-clockwise seen from outside.
  box.triangles = {{0, 2, 3}, {0, 3, 1},   // z min
                   {4, 5, 7}, {4, 7, 6},   // z max
                   {0, 1, 5}, {0, 5, 4},   // y min
                   {2, 6, 7}, {2, 7, 3},   // y max
                   {0, 4, 6}, {0, 6, 2},   // x min
                   {1, 3, 7}, {1, 7, 5}};  // x max
  if (inward_facing)
    for (Eigen::Vector3i& triangle : box.triangles) std::swap(triangle[1], triangle[2]);
  return box;
}

TriangleMesh makeSphere(const Eigen::Vector3f& centre, float radius, int subdivisions) {
  requireFinite(centre, "makeSphere: centre");
  requirePositive(radius, "makeSphere: radius");
  // 20 * 4^8 = 1.3 million triangles is already far finer than any test needs.
  if (subdivisions < 0 || subdivisions > 8)
    throw std::invalid_argument("makeSphere: subdivisions must be within [0, 8], got " +
                                std::to_string(subdivisions));
  const UnitIcosphere unit(subdivisions);
  TriangleMesh sphere;
  sphere.vertices.reserve(unit.vertices().size());
  for (const Eigen::Vector3d& direction : unit.vertices())
    sphere.vertices.push_back((centre.cast<double>() + double(radius) * direction).cast<float>());
  sphere.triangles = unit.triangles();
  return sphere;
}

TriangleMesh makeCylinder(const Eigen::Vector3f& base, float radius, float height, int segments) {
  requireFinite(base, "makeCylinder: base");
  requirePositive(radius, "makeCylinder: radius");
  requirePositive(height, "makeCylinder: height");
  if (segments < 3 || segments > (1 << 20))
    throw std::invalid_argument("makeCylinder: segments must be within [3, 2^20], got " +
                                std::to_string(segments));
  // Vertical axis through base; closed by two caps (fans around their centres).
  TriangleMesh cylinder;
  for (int i = 0; i < segments; ++i) {
    const double angle = 2.0 * M_PI * i / segments;
    const Eigen::Vector3f rim(static_cast<float>(radius * std::cos(angle)),
                              static_cast<float>(radius * std::sin(angle)), 0.0f);
    cylinder.vertices.push_back(base + rim);
    cylinder.vertices.push_back(base + rim + Eigen::Vector3f(0.0f, 0.0f, height));
  }
  const int bottom_centre = static_cast<int>(cylinder.vertices.size());
  cylinder.vertices.push_back(base);
  cylinder.vertices.push_back(base + Eigen::Vector3f(0.0f, 0.0f, height));
  const int top_centre = bottom_centre + 1;
  for (int i = 0; i < segments; ++i) {
    const int next = (i + 1) % segments;
    const int b0 = 2 * i, t0 = 2 * i + 1, b1 = 2 * next, t1 = 2 * next + 1;
    cylinder.triangles.emplace_back(b0, b1, t1);
    cylinder.triangles.emplace_back(b0, t1, t0);
    cylinder.triangles.emplace_back(bottom_centre, b1, b0);
    cylinder.triangles.emplace_back(top_centre, t0, t1);
  }
  return cylinder;
}

}  // namespace range_image_mapping::simulation
