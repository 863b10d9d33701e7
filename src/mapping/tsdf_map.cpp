#include "range_image_mapping/mapping/tsdf_map.h"

#include "number_text.h"

#include <cmath>

namespace range_image_mapping::mapping {

void TsdfMapOptions::validate() const {
  grid.validate();
  integrator.validate(grid);
  mesh.validate();
  // The integrator marks a block for re-meshing when a voxel crosses the
  // mesher's weight threshold: with two different thresholds blocks would
  // be re-meshed too late or for nothing.
  if (integrator.mesh_min_weight != mesh.min_weight)
    throw MappingError("integrator.mesh_min_weight (" + numberText(integrator.mesh_min_weight) +
                       ") must equal mesh.min_weight (" + numberText(mesh.min_weight) + ")");
  if (!(memory_radius_m >= 0.0) || !std::isfinite(memory_radius_m))
    throw MappingError("memory_radius_m must be >= 0 and finite (0 = keep everything), got " +
                       numberText(memory_radius_m));
  // A radius inside the clip would drop what the scan just wrote.
  if (memory_radius_m > 0.0 && !(memory_radius_m > integrator.max_range_m))
    throw MappingError("memory_radius_m must exceed the integrator's max_range_m (" +
                       numberText(integrator.max_range_m) + " m), got " + numberText(memory_radius_m));
  if (!(max_pose_jump_m >= 0.0) || !std::isfinite(max_pose_jump_m))
    throw MappingError("max_pose_jump_m must be >= 0 and finite (0 = accept any), got " +
                       numberText(max_pose_jump_m));
  if (max_refused_jumps < 1)
    throw MappingError("max_refused_jumps must be >= 1, got " + std::to_string(max_refused_jumps));
}

namespace {

const TsdfMapOptions& validated(const TsdfMapOptions& options) {
  options.validate();
  return options;
}

}  // namespace

TsdfMap::TsdfMap(TsdfMapOptions options)
    : options_(validated(options)),
      grid_(options_.grid),
      integrator_(options_.integrator),
      extractor_(options_.mesh) {}

MapUpdate TsdfMap::integrate(const RangeImage& scan, const ScanPose& pose,
                             const VertexNormalMap* normals) {
  MapUpdate update;
  const auto refuse = [&](std::string why) {
    ++scans_refused_;
    update.warning = "scan refused: " + std::move(why);
    return update;
  };
  try {
    integrator_.validate(grid_, scan, pose);
  } catch (const MappingError& error) {
    return refuse(error.what());
  }
  if (scan.validCount() == 0) return refuse("it has no valid pixels");

  // A pose far from the last one is more likely a broken pose source than
  // motion; integrating it would smear the map. Several in a row mean the
  // source really moved on (a relocalisation), so the jump is then taken.
  std::string jump_note;
  if (has_last_pose_ && options_.max_pose_jump_m > 0.0) {
    const double jump = (pose.world_from_lidar.translation() - last_pose_.translation()).norm();
    if (jump > options_.max_pose_jump_m) {
      if (refused_jumps_ < options_.max_refused_jumps) {
        ++refused_jumps_;
        return refuse("the pose jumped " + numberText(jump) + " m from the last integrated pose (limit " +
                      numberText(options_.max_pose_jump_m) + " m; refusal " + std::to_string(refused_jumps_) +
                      " of " + std::to_string(options_.max_refused_jumps) + " before the new position is taken)");
      }
      jump_note = "the pose jumped " + numberText(jump) + " m; taken after " + std::to_string(refused_jumps_) +
                  " refusals in a row";
    }
  }

  update.integration = integrator_.integrate(grid_, scan, pose, normals);
  update.integrated = true;
  ++scans_integrated_;
  has_last_pose_ = true;
  last_pose_ = pose.world_from_lidar;
  refused_jumps_ = 0;
  if (options_.memory_radius_m > 0.0) {
    const std::vector<BlockKey> far =
        grid_.blocksFartherThan(pose.world_from_lidar.translation(), options_.memory_radius_m);
    if (!far.empty() && options_.keep_dropped_mesh) {
      extractor_.update(grid_);  // their chunks, current before the blocks go
      for (const BlockKey& key : far)
        if (const MeshChunk* chunk = extractor_.chunk(key)) dropped_chunks_.push_back(*chunk);
    }
    for (const BlockKey& key : far) grid_.remove(key);
    update.blocks_dropped = far.size();
  }

  update.warning = jump_note;
  if (update.integration.blocks_refused > 0) {
    if (!update.warning.empty()) update.warning += "; ";
    update.warning += std::to_string(update.integration.blocks_refused) +
                      " blocks not created: the memory budget (max_blocks " +
                      std::to_string(options_.grid.max_blocks) + ") is reached, part of the scan is not mapped";
  }
  return update;
}

MeshUpdate TsdfMap::updateMesh() { return extractor_.update(grid_); }

MapStatistics TsdfMap::statistics() const {
  MapStatistics statistics;
  statistics.scans_integrated = scans_integrated_;
  statistics.scans_refused = scans_refused_;
  statistics.blocks = grid_.blockCount();
  statistics.memory_bytes = grid_.memoryBytes();
  statistics.triangles = extractor_.triangleCount();
  return statistics;
}

TriangleMesh TsdfMap::fullMesh() {
  // Every block, whatever the update budget and the tolerance that lets
  // slightly changed blocks wait: a saved mesh is exactly the map's.
  extractor_.update(grid_, /*force_all=*/true);
  TriangleMesh mesh = extractor_.combined();
  for (const MeshChunk& chunk : dropped_chunks_) {
    const int offset = int(mesh.vertices.size());
    mesh.vertices.insert(mesh.vertices.end(), chunk.vertices.begin(), chunk.vertices.end());
    mesh.normals.insert(mesh.normals.end(), chunk.normals.begin(), chunk.normals.end());
    mesh.intensities.insert(mesh.intensities.end(), chunk.intensities.begin(), chunk.intensities.end());
    for (const Eigen::Vector3i& triangle : chunk.triangles)
      mesh.triangles.push_back(triangle + Eigen::Vector3i::Constant(offset));
  }
  return mesh;
}

void TsdfMap::reset() {
  grid_.clear();
  extractor_.clear();
  has_last_pose_ = false;
  last_pose_ = Eigen::Isometry3d::Identity();
  refused_jumps_ = 0;
  dropped_chunks_.clear();
  scans_integrated_ = scans_refused_ = 0;
}

}  // namespace range_image_mapping::mapping
