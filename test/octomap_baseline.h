// OctoMap (Hornung et al. 2013) as the paper's occupancy baseline: the same
// scans, as world-frame points within the same range clip, inserted with
// OcTree::insertPointCloud at the same resolution from the sensor origin. Its
// surface estimate is the centres of the occupied leaves. For tests and
// benchmarks only: OctoMap is never a dependency of the core.
#pragma once

#include "range_image_mapping/range_image.h"
#include "range_image_mapping/scan_motion.h"

#include <Eigen/Geometry>

#include <cstddef>
#include <memory>
#include <vector>

namespace octomap {
class OcTree;
}

namespace range_image_mapping::test {

struct OctomapBaselineOptions {
  double resolution_m = 0.1;
  // Pixels outside [min, max] are not inserted at all, as the TSDF integrator
  // never writes them (no free-space ray for a clipped return either).
  double min_range_m = 0.3;
  double max_range_m = 30.0;
  // OctoMap's option to merge end points that fall into one leaf before ray
  // casting (faster, slightly different counts); off, as octomap_server has it.
  bool discretize = false;
};

// Time spent in insertPointCloud alone: wall, and CPU time of the calling
// thread (OctoMap inserts on one thread; the CPU time does not depend on what
// else the machine runs).
struct OctomapInsertionTime {
  double wall_s = 0.0, cpu_s = 0.0;
};

class OctomapBaseline {
 public:
  explicit OctomapBaseline(OctomapBaselineOptions options);  // throws std::invalid_argument for bad options
  ~OctomapBaseline();

  // Unprojects the valid pixels in range, moves each column to the scan time
  // with the twist (the deskew the TSDF integrator applies), then into the
  // world; inserts them with the sensor origin at the pose's translation.
  OctomapInsertionTime insert(const RangeImage& scan, const Eigen::Isometry3d& world_from_lidar,
                               const Twist& twist = Twist::Zero());

  // Centres of the occupied leaves (pruned leaves expanded to the resolution,
  // so the estimate's density matches the voxel grid's).
  std::vector<Eigen::Vector3f> occupiedCentres() const;
  std::size_t leafCount() const;
  std::size_t memoryBytes() const;
  const OctomapInsertionTime& totalInsertionTime() const { return total_time_; }
  std::size_t insertedPoints() const { return inserted_points_; }

 private:
  OctomapBaselineOptions options_;
  std::unique_ptr<octomap::OcTree> tree_;
  std::vector<ColumnMotion> column_motion_;
  OctomapInsertionTime total_time_;
  std::size_t inserted_points_ = 0;
};

}  // namespace range_image_mapping::test
