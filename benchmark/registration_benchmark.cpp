// Full multi-scale projective registration of two real 128 x 1024 Ouster
// frames (lb_n3 1795 -> 1796) on 2 threads, against baselines in the same run:
//   single-scale  the same projective ICP at full resolution only (10 + 20 + 20
//                 = 50 iterations at stride 1, the same budget)
//   PCL ICP       pcl::IterativeClosestPointWithNormals (point-to-plane, k-d
//                 tree correspondences) on the same points with our normals,
//                 the same 1 m gate and 50 iterations at most
// Each is timed from the range images (normals, pyramid, k-d tree included)
// to the pose, and its error against the reference poses is printed.
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/registration/projective_icp.h"
#include "test_data.h"

#include <pcl/point_types.h>
#include <pcl/registration/icp.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <vector>

namespace range_image_mapping {
namespace {

using Clock = std::chrono::steady_clock;
constexpr int kThreads = 2;

struct Timing {
  double median_ms = 0.0;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
};

// Median wall time of `repetitions` runs (the first one warms caches up and is not counted).
Timing measure(int repetitions, const std::function<Eigen::Isometry3d()>& run) {
  Timing timing;
  timing.pose = run();
  std::vector<double> times;
  for (int k = 0; k < repetitions; ++k) {
    const auto start = Clock::now();
    timing.pose = run();
    times.push_back(std::chrono::duration<double, std::milli>(Clock::now() - start).count());
  }
  std::sort(times.begin(), times.end());
  timing.median_ms = times[times.size() / 2];
  return timing;
}

void printError(const char* name, const Timing& timing, const Eigen::Isometry3d& truth) {
  const Eigen::Isometry3d error = truth.inverse() * timing.pose;
  std::printf("%-28s %9.2f ms  %7.1f frames/s   error %.2f cm %.4f deg\n", name, timing.median_ms,
              1000.0 / timing.median_ms, error.translation().norm() * 100,
              Eigen::AngleAxisd(error.linear()).angle() * 180.0 / M_PI);
}

pcl::PointCloud<pcl::PointNormal>::Ptr pclCloud(const VertexNormalMap& map) {
  pcl::PointCloud<pcl::PointNormal>::Ptr cloud(new pcl::PointCloud<pcl::PointNormal>);
  for (std::size_t i = 0; i < map.points.size(); ++i) {
    if (!std::isfinite(map.normals[i].x())) continue;
    pcl::PointNormal point;
    point.x = map.points[i].x();
    point.y = map.points[i].y();
    point.z = map.points[i].z();
    point.normal_x = map.normals[i].x();
    point.normal_y = map.normals[i].y();
    point.normal_z = map.normals[i].z();
    cloud->push_back(point);
  }
  return cloud;
}

int run() {
  const std::string pcap = test::dataFile("ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  const std::string json = test::dataFile("ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const std::string poses_path = test::dataFile("ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt");
  if (pcap.empty() || json.empty() || poses_path.empty()) {
    std::fprintf(stderr, "registration_benchmark needs ../shared/data/ouster-pcaps (or $RIM_DATA_DIR)\n");
    return 1;
  }
  const OusterMetadata metadata = loadOusterMetadata(json);
  std::vector<RangeImage> frames = io::readOusterRangeImages(pcap, metadata);
  if (frames.size() < 2) {
    std::fprintf(stderr, "lb_n3 decoded into %zu frames, expected 3\n", frames.size());
    return 1;
  }
  const std::vector<Eigen::Isometry3d> sensor_poses = io::readKittiPoses(poses_path);
  const Eigen::Isometry3d& lidar_to_sensor = metadata.intrinsics.lidar_to_sensor;
  const Eigen::Isometry3d truth =
      (sensor_poses[0] * lidar_to_sensor).inverse() * (sensor_poses[1] * lidar_to_sensor);

  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, kThreads);
  std::printf("lb_n3 frames %u -> %u (%d x %d), %d threads, median of the runs\n", frames[0].frame_id,
              frames[1].frame_id, frames[0].rows(), frames[0].columns(), kThreads);

  // Where the time goes: normals of one frame, the target pyramid, ICP alone.
  VertexNormalMap scratch;
  const Timing normals = measure(20, [&] {
    computeVertexNormalMap(frames[1], 1, {}, scratch);
    return Eigen::Isometry3d::Identity();
  });
  std::printf("%-28s %9.2f ms\n", "normal map (full, cross)", normals.median_ms);
  NormalMapOptions covariance_options;
  covariance_options.method = NormalMethod::kCovariance;
  const Timing covariance = measure(10, [&] {
    computeVertexNormalMap(frames[1], 1, covariance_options, scratch);
    return Eigen::Isometry3d::Identity();
  });
  std::printf("%-28s %9.2f ms\n", "normal map (full, 3x3 cov.)", covariance.median_ms);
  registration::ProjectiveIcp alone;
  alone.setTarget(frames[0]);
  computeVertexNormalMap(frames[1], 1, {}, scratch);
  const Timing align_only = measure(20, [&] { return alone.align(scratch, Eigen::Isometry3d::Identity()).target_from_source; });
  std::printf("%-28s %9.2f ms\n", "align only (multi-scale)", align_only.median_ms);

  // Multi-scale, as the odometry runs it: target pyramid + source normals + ICP.
  registration::ProjectiveIcp multi_scale;
  const Timing ours = measure(20, [&] {
    multi_scale.setTarget(frames[0]);
    return multi_scale.align(frames[1], Eigen::Isometry3d::Identity()).target_from_source;
  });
  printError("projective multi-scale", ours, truth);

  registration::RegistrationOptions single_options;
  single_options.strides = {1};
  single_options.iterations = {50};
  registration::ProjectiveIcp single_scale(single_options);
  const Timing single = measure(10, [&] {
    single_scale.setTarget(frames[0]);
    return single_scale.align(frames[1], Eigen::Isometry3d::Identity()).target_from_source;
  });
  printError("projective single-scale", single, truth);

  // PCL gets our normals (their computation is not part of its time).
  VertexNormalMap target_map, source_map;
  computeVertexNormalMap(frames[0], 1, {}, target_map);
  computeVertexNormalMap(frames[1], 1, {}, source_map);
  const auto target_cloud = pclCloud(target_map), source_cloud = pclCloud(source_map);
  const Timing pcl_icp = measure(2, [&] {
    pcl::IterativeClosestPointWithNormals<pcl::PointNormal, pcl::PointNormal, double> icp;
    icp.setMaxCorrespondenceDistance(1.0);
    icp.setMaximumIterations(50);
    icp.setTransformationEpsilon(1e-10);
    icp.setInputTarget(target_cloud);  // builds the k-d tree
    icp.setInputSource(source_cloud);
    pcl::PointCloud<pcl::PointNormal> aligned;
    icp.align(aligned);
    return Eigen::Isometry3d(icp.getFinalTransformation());
  });
  printError("PCL point-to-plane ICP", pcl_icp, truth);
  std::printf("points: target %zu, source %zu with normals\n", target_cloud->size(), source_cloud->size());
  std::printf("speed-up of multi-scale projective ICP: %.1fx over single-scale, %.1fx over PCL\n",
              single.median_ms / ours.median_ms, pcl_icp.median_ms / ours.median_ms);
  return 0;
}

}  // namespace
}  // namespace range_image_mapping

int main() { return range_image_mapping::run(); }
