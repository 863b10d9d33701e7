// Level of detail for displaying a live mesh: the mesh is split into pieces
// (the Mapper's marker chunks), each shown at a level picked by its distance
// from a viewpoint, and all levels are coarsened together until the shown
// triangles fit a budget. A level is vertex clustering (Rossignac and Borrel)
// on a grid anchored at the origin whose cell doubles per level, so the cells
// of one level nest in the next and neighbouring pieces at the same level
// merge their shared border the same way. Display only: what is saved is the
// map's full mesh.
#pragma once

#include "range_image_mapping/triangle_mesh.h"

#include <Eigen/Geometry>

#include <cstddef>
#include <memory>
#include <optional>
#include <unordered_map>
#include <vector>

namespace range_image_mapping::mapping {

// Merges the vertices in each cube of cell_size_m into their mean (normals
// averaged and normalised, intensities averaged); triangles whose corners
// fall in fewer than three cells are dropped, and a triangle on the same
// three cells is kept once. Every point of the result lies within
// sqrt(3) * cell_size_m of the input surface (each kept triangle is a
// corner-wise move of an input triangle by at most a cell's diagonal).
// cell_size_m 0 returns the mesh as it is. Vertices on a face of `border`
// (within 1e-5 m) keep their exact place, so pieces of a mesh cut along those
// faces still meet without cracks whatever cells each was clustered into.
// Throws std::invalid_argument for a negative or non-finite cell size or a
// triangle index out of range.
TriangleMesh clusterVertices(const TriangleMesh& mesh, double cell_size_m,
                             const std::optional<Eigen::AlignedBox3f>& border = std::nullopt);

struct LevelOfDetailOptions {
  // Level 0 is the mesh as it is; level L clusters into cells of
  // voxel_size_m * 2^L.
  double voxel_size_m = 0.1;
  // Pieces nearer the viewpoint than this are shown at level 0; each doubling
  // of the distance adds a level. 0: every piece at level 0 (the budget alone
  // coarsens).
  double full_detail_distance_m = 10.0;
  // Most triangles shown; 0: no budget. Over it, every piece goes one level
  // coarser until the total fits; if the coarsest level still does not fit,
  // the farthest pieces are left out.
  std::size_t triangle_budget = 0;
  int max_level = 8;
  // Throws std::invalid_argument naming the field.
  void validate() const;
};

// The level of a piece at this distance from the viewpoint, before the budget.
int levelForDistance(double distance_m, const LevelOfDetailOptions& options);

class MeshLevelOfDetail {
 public:
  using Key = Eigen::Vector3i;

  explicit MeshLevelOfDetail(LevelOfDetailOptions options);

  // A piece's full mesh (replacing what it had); an empty mesh removes it.
  // region: the box the piece was cut from; its vertices on the box's faces,
  // which the neighbouring pieces share, keep their place at every level.
  void setPiece(const Key& key, TriangleMesh mesh, const std::optional<Eigen::AlignedBox3f>& region = std::nullopt);
  void removePiece(const Key& key);
  void clear();

  // Picks every piece's level for this viewpoint under the budget. Returns
  // the pieces whose shown mesh changed since the last call (a new level, new
  // content, removed or left out); their meshes are then shown(key).
  std::vector<Key> update(const Eigen::Vector3f& viewpoint);
  // The piece's mesh at its level; nullptr when it is left out or unknown.
  const TriangleMesh* shown(const Key& key) const;
  int levelOf(const Key& key) const;  // -1: left out or unknown
  std::size_t shownTriangles() const { return shown_triangles_; }
  std::size_t fullTriangles() const { return full_triangles_; }
  std::size_t pieceCount() const { return pieces_.size(); }
  const LevelOfDetailOptions& options() const { return options_; }

 private:
  struct Piece {
    std::vector<TriangleMesh> levels;  // built on demand, each from the one before
    Eigen::AlignedBox3f bounds;
    std::optional<Eigen::AlignedBox3f> region;
    int shown_level = -1;  // -1: not shown
    bool changed = true;
  };
  struct KeyHash {
    std::size_t operator()(const Key& key) const;
  };
  const TriangleMesh& level(Piece& piece, int level) const;

  LevelOfDetailOptions options_;
  std::unordered_map<Key, Piece, KeyHash> pieces_;
  std::vector<Key> removed_;  // since the last update
  std::size_t shown_triangles_ = 0, full_triangles_ = 0;
};

}  // namespace range_image_mapping::mapping
