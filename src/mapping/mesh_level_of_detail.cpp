#include "range_image_mapping/mapping/mesh_level_of_detail.h"
#include "range_image_mapping/lattice_key.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <unordered_set>
#include <utility>

namespace range_image_mapping::mapping {
namespace {

struct TriangleHash {
  std::size_t operator()(const std::array<int, 3>& corners) const {
    return std::size_t(corners[0]) * 0x9E3779B97F4A7C15ull ^ std::size_t(corners[1]) * 0xC2B2AE3D27D4EB4Full ^
           std::size_t(corners[2]);
  }
};

double cellSize(const LevelOfDetailOptions& options, int level) { return options.voxel_size_m * std::ldexp(1.0, level); }

}  // namespace

TriangleMesh clusterVertices(const TriangleMesh& mesh, double cell_size_m,
                             const std::optional<Eigen::AlignedBox3f>& border) {
  if (!(cell_size_m >= 0.0) || !std::isfinite(cell_size_m))
    throw std::invalid_argument("clusterVertices: the cell size must be finite and not negative, not " +
                                std::to_string(cell_size_m));
  const int vertex_count = int(mesh.vertices.size());
  for (const Eigen::Vector3i& triangle : mesh.triangles)
    if ((triangle.array() < 0).any() || (triangle.array() >= vertex_count).any())
      throw std::invalid_argument("clusterVertices: a triangle indexes a vertex out of range (" +
                                  std::to_string(vertex_count) + " vertices)");
  if (cell_size_m == 0.0) return mesh;
  const bool with_normals = mesh.normals.size() == mesh.vertices.size();
  const bool with_intensities = mesh.intensities.size() == mesh.vertices.size();

  constexpr float kOnBorder_m = 1e-5f;
  const auto onBorder = [&](const Eigen::Vector3f& vertex) {
    return border && (((vertex - border->min()).array().abs() <= kOnBorder_m).any() ||
                      ((vertex - border->max()).array().abs() <= kOnBorder_m).any());
  };
  // Each input vertex's cluster, clusters in order of first appearance; a
  // vertex on the border is a cluster of its own.
  std::unordered_map<Eigen::Vector3i, int, LatticeKeyHash> cluster_of_cell;
  std::vector<int> cluster_of_vertex(mesh.vertices.size());
  std::vector<Eigen::Vector3d> position_sums, normal_sums;
  std::vector<double> intensity_sums;
  std::vector<int> counts;
  for (int i = 0; i < vertex_count; ++i) {
    const Eigen::Vector3f& vertex = mesh.vertices[i];
    int cluster = int(counts.size());
    if (!onBorder(vertex)) {
      const Eigen::Vector3i cell = (vertex.cast<double>() / cell_size_m).array().floor().cast<int>();
      cluster = cluster_of_cell.try_emplace(cell, cluster).first->second;
    }
    if (cluster == int(counts.size())) {
      position_sums.emplace_back(Eigen::Vector3d::Zero());
      normal_sums.emplace_back(Eigen::Vector3d::Zero());
      intensity_sums.push_back(0.0);
      counts.push_back(0);
    }
    cluster_of_vertex[i] = cluster;
    position_sums[cluster] += vertex.cast<double>();
    if (with_normals) normal_sums[cluster] += mesh.normals[i].cast<double>();
    if (with_intensities) intensity_sums[cluster] += mesh.intensities[i];
    ++counts[cluster];
  }

  // Only clusters a kept triangle uses become vertices.
  std::vector<int> vertex_of_cluster(counts.size(), -1);
  TriangleMesh result;
  std::unordered_set<std::array<int, 3>, TriangleHash> kept;
  const auto vertexOf = [&](int cluster) {
    int& vertex = vertex_of_cluster[cluster];
    if (vertex >= 0) return vertex;
    vertex = int(result.vertices.size());
    const double count = counts[cluster];
    result.vertices.push_back((position_sums[cluster] / count).cast<float>());
    if (with_normals) {
      const double length = normal_sums[cluster].norm();
      result.normals.push_back(length > 1e-9 ? Eigen::Vector3f((normal_sums[cluster] / length).cast<float>())
                                             : Eigen::Vector3f::UnitZ());
    }
    if (with_intensities) result.intensities.push_back(float(intensity_sums[cluster] / count));
    return vertex;
  };
  for (const Eigen::Vector3i& triangle : mesh.triangles) {
    const int a = cluster_of_vertex[triangle[0]], b = cluster_of_vertex[triangle[1]],
              c = cluster_of_vertex[triangle[2]];
    if (a == b || b == c || a == c) continue;
    std::array<int, 3> sorted{a, b, c};
    std::sort(sorted.begin(), sorted.end());
    if (!kept.insert(sorted).second) continue;
    result.triangles.emplace_back(vertexOf(a), vertexOf(b), vertexOf(c));
  }
  return result;
}

void LevelOfDetailOptions::validate() const {
  const auto fail = [](const std::string& message) { throw std::invalid_argument("level of detail: " + message); };
  if (!(voxel_size_m > 0.0) || !std::isfinite(voxel_size_m))
    fail("voxel_size_m must be positive and finite, not " + std::to_string(voxel_size_m));
  if (!(full_detail_distance_m >= 0.0) || !std::isfinite(full_detail_distance_m))
    fail("full_detail_distance_m must be finite and not negative, not " + std::to_string(full_detail_distance_m));
  if (max_level < 0 || max_level > 20) fail("max_level must be within [0, 20], not " + std::to_string(max_level));
}

int levelForDistance(double distance_m, const LevelOfDetailOptions& options) {
  if (options.full_detail_distance_m <= 0.0 || distance_m <= options.full_detail_distance_m) return 0;
  // Cells as wide as the full-detail ones look from the full-detail distance.
  const int level = int(std::ceil(std::log2(distance_m / options.full_detail_distance_m)));
  return std::clamp(level, 0, options.max_level);
}

std::size_t MeshLevelOfDetail::KeyHash::operator()(const Key& key) const { return LatticeKeyHash()(key); }

MeshLevelOfDetail::MeshLevelOfDetail(LevelOfDetailOptions options) : options_(options) { options_.validate(); }

void MeshLevelOfDetail::setPiece(const Key& key, TriangleMesh mesh, const std::optional<Eigen::AlignedBox3f>& region) {
  if (mesh.triangles.empty()) {
    removePiece(key);
    return;
  }
  Piece& piece = pieces_[key];
  if (!piece.levels.empty()) full_triangles_ -= piece.levels.front().triangles.size();
  piece.bounds = mesh.bounds();
  piece.region = region;
  full_triangles_ += mesh.triangles.size();
  piece.levels.clear();
  piece.levels.push_back(std::move(mesh));
  piece.changed = true;
}

void MeshLevelOfDetail::removePiece(const Key& key) {
  const auto found = pieces_.find(key);
  if (found == pieces_.end()) return;
  full_triangles_ -= found->second.levels.front().triangles.size();
  if (found->second.shown_level >= 0) removed_.push_back(key);
  pieces_.erase(found);
}

void MeshLevelOfDetail::clear() {
  pieces_.clear();
  removed_.clear();
  shown_triangles_ = full_triangles_ = 0;
}

const TriangleMesh& MeshLevelOfDetail::level(Piece& piece, int level) const {
  // Cells nest (anchored at the origin, doubling), so clustering the level
  // above keeps every vertex within its cell of this level: the error bound
  // of clusterVertices holds against the full mesh.
  while (int(piece.levels.size()) <= level) {
    const int next = int(piece.levels.size());
    piece.levels.push_back(clusterVertices(piece.levels.back(), cellSize(options_, next), piece.region));
  }
  return piece.levels[level];
}

std::vector<MeshLevelOfDetail::Key> MeshLevelOfDetail::update(const Eigen::Vector3f& viewpoint) {
  struct Candidate {
    Piece* piece;
    const Key* key;
    float distance_m;
    int base_level;
    int level = -1;
  };
  std::vector<Candidate> candidates;
  candidates.reserve(pieces_.size());
  for (auto& [key, piece] : pieces_) {
    const float distance = piece.bounds.exteriorDistance(viewpoint);
    candidates.push_back({&piece, &key, distance, levelForDistance(distance, options_)});
  }
  // Coarsen everything together, one level at a time, until the budget holds.
  std::size_t total = 0;
  for (int shift = 0;; ++shift) {
    total = 0;
    bool all_coarsest = true;
    for (Candidate& candidate : candidates) {
      candidate.level = std::min(candidate.base_level + shift, options_.max_level);
      all_coarsest = all_coarsest && candidate.level == options_.max_level;
      total += level(*candidate.piece, candidate.level).triangles.size();
    }
    if (options_.triangle_budget == 0 || total <= options_.triangle_budget || all_coarsest) break;
  }
  if (options_.triangle_budget > 0 && total > options_.triangle_budget) {
    // Even the coarsest level is too much: the farthest pieces go.
    std::sort(candidates.begin(), candidates.end(),
              [](const Candidate& a, const Candidate& b) { return a.distance_m > b.distance_m; });
    for (Candidate& candidate : candidates) {
      if (total <= options_.triangle_budget) break;
      total -= level(*candidate.piece, candidate.level).triangles.size();
      candidate.level = -1;
    }
  }
  std::vector<Key> changed = std::move(removed_);
  removed_.clear();
  for (Candidate& candidate : candidates) {
    Piece& piece = *candidate.piece;
    if (piece.changed || piece.shown_level != candidate.level) {
      if (piece.shown_level >= 0 || candidate.level >= 0) changed.push_back(*candidate.key);
      piece.shown_level = candidate.level;
      piece.changed = false;
    }
  }
  shown_triangles_ = total;
  return changed;
}

const TriangleMesh* MeshLevelOfDetail::shown(const Key& key) const {
  const auto found = pieces_.find(key);
  if (found == pieces_.end() || found->second.shown_level < 0) return nullptr;
  return &found->second.levels.at(found->second.shown_level);
}

int MeshLevelOfDetail::levelOf(const Key& key) const {
  const auto found = pieces_.find(key);
  return found == pieces_.end() ? -1 : found->second.shown_level;
}

}  // namespace range_image_mapping::mapping
