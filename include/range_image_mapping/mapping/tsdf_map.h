// The mapping stack as one object, as the Mapper nodelet, `rim map` and
// `rim run` use it: checks each scan's pose, integrates it into the voxel
// block grid, keeps memory bounded around the sensor and the mesh up to date.
#pragma once

#include "range_image_mapping/mapping/marching_cubes.h"
#include "range_image_mapping/mapping/tsdf_integrator.h"
#include "range_image_mapping/mapping/voxel_block_grid.h"

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace range_image_mapping::mapping {

struct TsdfMapOptions {
  VoxelBlockGridOptions grid;
  TsdfIntegratorOptions integrator;
  MeshOptions mesh;
  // Blocks farther than this from the sensor are dropped after each scan
  // (0 = keep everything). Must exceed the integrator's max range.
  double memory_radius_m = 0.0;
  // Keep the mesh of dropped blocks (in memory, a small fraction of their
  // voxels), so fullMesh() covers the whole run. Off for runs that must stay
  // at flat memory.
  bool keep_dropped_mesh = true;
  // A pose this far (metres) from the last integrated one is refused as a
  // jump (0 = accept any); after max_refused_jumps refusals in a row the new
  // position is accepted, since the pose source has really moved on.
  double max_pose_jump_m = 20.0;
  int max_refused_jumps = 3;
  // Throws MappingError naming the field.
  void validate() const;
};

struct MapUpdate {
  IntegrationStatistics integration;
  std::size_t blocks_dropped = 0;  // by the memory radius
  bool integrated = false;         // false: refused, see warning
  std::string warning;             // why the scan was refused or only partly used; empty if none
};

struct MapStatistics {
  std::size_t scans_integrated = 0, scans_refused = 0;
  std::size_t blocks = 0, memory_bytes = 0, triangles = 0;
};

class TsdfMap {
 public:
  explicit TsdfMap(TsdfMapOptions options);  // validates

  // Never throws for bad data: a non-finite pose or twist, a jump or an
  // unusable image is refused with a warning and the map stays as it was.
  // normals: as TsdfIntegrator::integrate().
  MapUpdate integrate(const RangeImage& scan, const ScanPose& pose,
                      const VertexNormalMap* normals = nullptr);
  // Re-meshes what changed since the last call.
  MeshUpdate updateMesh();
  const MeshExtractor& mesh() const { return extractor_; }
  const VoxelBlockGrid& grid() const { return grid_; }
  const TsdfMapOptions& options() const { return options_; }
  MapStatistics statistics() const;
  // The mesh of the whole run: the current grid's (updated first) plus the
  // kept chunks of dropped blocks (saved with io::saveMeshFile).
  TriangleMesh fullMesh();
  const std::vector<MeshChunk>& droppedChunks() const { return dropped_chunks_; }
  void reset();

 private:
  TsdfMapOptions options_;
  VoxelBlockGrid grid_;
  TsdfIntegrator integrator_;
  MeshExtractor extractor_;
  bool has_last_pose_ = false;
  Eigen::Isometry3d last_pose_ = Eigen::Isometry3d::Identity();
  int refused_jumps_ = 0;
  std::vector<MeshChunk> dropped_chunks_;
  std::size_t scans_integrated_ = 0, scans_refused_ = 0;
};

}  // namespace range_image_mapping::mapping
