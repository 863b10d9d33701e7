#include "octomap_baseline.h"

#include <octomap/OcTree.h>

#include <chrono>
#include <cmath>
#include <ctime>
#include <stdexcept>
#include <string>

namespace range_image_mapping::test {
namespace {

double threadCpuSeconds() {
  timespec time{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &time);
  return double(time.tv_sec) + 1e-9 * double(time.tv_nsec);
}

}  // namespace

OctomapBaseline::OctomapBaseline(OctomapBaselineOptions options) : options_(options) {
  if (!(options_.resolution_m > 0.0) || !std::isfinite(options_.resolution_m))
    throw std::invalid_argument("OctomapBaseline: resolution_m must be positive, not " +
                                std::to_string(options_.resolution_m));
  if (!(options_.min_range_m >= 0.0) || !(options_.max_range_m > options_.min_range_m))
    throw std::invalid_argument("OctomapBaseline: need 0 <= min_range_m < max_range_m");
  tree_ = std::make_unique<octomap::OcTree>(options_.resolution_m);
}

OctomapBaseline::~OctomapBaseline() = default;

OctomapInsertionTime OctomapBaseline::insert(const RangeImage& scan, const Eigen::Isometry3d& world_from_lidar,
                                             const Twist& twist) {
  if (!scan.model || scan.column_order != ColumnOrder::kStaggered)
    throw std::invalid_argument("OctomapBaseline: the scan needs a model and staggered columns");
  const bool moving = computeColumnMotion(scan, scanTime(scan, ScanTimeSource::kFirstValidColumn), twist, column_motion_);
  const Eigen::Isometry3f world_from_lidar_f = world_from_lidar.cast<float>();
  const LidarModel& model = *scan.model;
  octomap::Pointcloud cloud;
  cloud.reserve(scan.validCount());
  for (int v = 0; v < scan.rows(); ++v)
    for (int u = 0; u < scan.columns(); ++u) {
      const float range = scan.at(v, u);
      if (!isValidRange(range) || range < options_.min_range_m || range > options_.max_range_m) continue;
      Eigen::Vector3f point = model.unproject(u, v, range);
      if (moving) point = column_motion_[u] * point.homogeneous();
      point = world_from_lidar_f * point;
      cloud.push_back(point.x(), point.y(), point.z());
    }
  const Eigen::Vector3d origin = world_from_lidar.translation();
  const auto wall_start = std::chrono::steady_clock::now();
  const double cpu_start = threadCpuSeconds();
  tree_->insertPointCloud(cloud, octomap::point3d(float(origin.x()), float(origin.y()), float(origin.z())),
                          -1.0, false, options_.discretize);
  OctomapInsertionTime time;
  time.cpu_s = threadCpuSeconds() - cpu_start;
  time.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  total_time_.wall_s += time.wall_s;
  total_time_.cpu_s += time.cpu_s;
  inserted_points_ += cloud.size();
  return time;
}

std::vector<Eigen::Vector3f> OctomapBaseline::occupiedCentres() const {
  std::vector<Eigen::Vector3f> centres;
  const double resolution = tree_->getResolution();
  for (auto leaf = tree_->begin_leafs(), end = tree_->end_leafs(); leaf != end; ++leaf) {
    if (!tree_->isNodeOccupied(*leaf)) continue;
    const octomap::point3d centre = leaf.getCoordinate();
    // A pruned leaf stands for cells^3 occupied voxels of the finest size.
    const int cells = int(std::lround(leaf.getSize() / resolution));
    const double first = -0.5 * leaf.getSize() + 0.5 * resolution;
    for (int i = 0; i < cells; ++i)
      for (int j = 0; j < cells; ++j)
        for (int k = 0; k < cells; ++k)
          centres.emplace_back(float(centre.x() + first + i * resolution), float(centre.y() + first + j * resolution),
                               float(centre.z() + first + k * resolution));
  }
  return centres;
}

std::size_t OctomapBaseline::leafCount() const { return tree_->getNumLeafNodes(); }

std::size_t OctomapBaseline::memoryBytes() const { return tree_->memoryUsage(); }

}  // namespace range_image_mapping::test
