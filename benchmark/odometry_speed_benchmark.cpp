// Frames per second of the full odometry step (registration::LidarOdometry::
// process: deskew, normals, pyramid, multi-scale ICP, next target) on 2
// threads, against PCL GICP on the same consecutive pairs in the same run
// (voxel filtering, covariances, k-d trees and alignment included, from the
// identity; PCL recomputes the target each pair, as its API requires).
//
// Usage: odometry_speed_benchmark [SIMULATED_DIR | lb_n3] [pcl_pairs=20] [voxel_m=0.2]
//   SIMULATED_DIR  a `rim simulate` Ouster directory (metadata.json, capture.pcap)
//   lb_n3          the real 128 x 1024 recording in the data directory (default)
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/registration/lidar_odometry.h"
#include "test_data.h"

#include <pcl/filters/voxel_grid.h>
#include <pcl/point_types.h>
#include <pcl/registration/gicp.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using Clock = std::chrono::steady_clock;
using PointCloud = pcl::PointCloud<pcl::PointXYZ>;
constexpr int kThreads = 2;

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

PointCloud::Ptr downsampledCloud(const RangeImage& image, double voxel_m) {
  PointCloud::Ptr cloud(new PointCloud);
  for (const Eigen::Vector3f& point : image.unprojectAll()) cloud->push_back(pcl::PointXYZ(point.x(), point.y(), point.z()));
  PointCloud::Ptr downsampled(new PointCloud);
  pcl::VoxelGrid<pcl::PointXYZ> grid;
  grid.setLeafSize(float(voxel_m), float(voxel_m), float(voxel_m));
  grid.setInputCloud(cloud);
  grid.filter(*downsampled);
  return downsampled;
}

int run(int argc, char** argv) {
  const std::string source = argc > 1 ? argv[1] : "lb_n3";
  const int pcl_pairs = argc > 2 ? std::atoi(argv[2]) : 20;
  const double voxel_m = argc > 3 ? std::atof(argv[3]) : 0.2;
  if (pcl_pairs < 1 || !(voxel_m > 0.0)) {
    std::fprintf(stderr, "pcl_pairs must be >= 1 and voxel_m > 0\n");
    return 2;
  }
  std::string pcap, json;
  if (source == "lb_n3") {
    pcap = test::dataFile("ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
    json = test::dataFile("ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
    if (pcap.empty() || json.empty()) {
      std::fprintf(stderr, "lb_n3 needs ../shared/data/ouster-pcaps (or $RIM_DATA_DIR)\n");
      return 1;
    }
  } else {
    pcap = source + "/capture.pcap";
    json = source + "/metadata.json";
  }
  const OusterMetadata metadata = loadOusterMetadata(json);
  std::vector<RangeImage> frames = io::readOusterRangeImages(pcap, metadata);
  if (frames.size() < 2) {
    std::fprintf(stderr, "%s: %zu scans decoded, need at least 2\n", source.c_str(), frames.size());
    return 1;
  }

  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, kThreads);
  std::printf("%s: %zu scans %d x %d, %d threads\n", source.c_str(), frames.size(), frames[0].rows(),
              frames[0].columns(), kThreads);

  // Odometry over the whole sequence, twice: the first pass warms caches and
  // sizes the buffers, the second is timed (steady state, no allocation).
  registration::LidarOdometry odometry;
  for (const RangeImage& frame : frames) odometry.process(frame);
  odometry.reset();
  std::vector<double> step_seconds;
  for (const RangeImage& frame : frames) {
    const auto start = Clock::now();
    odometry.process(frame);
    step_seconds.push_back(secondsSince(start));
  }
  // The first step of a run only builds the target: not a registration.
  step_seconds.erase(step_seconds.begin());
  double ours_total = 0.0;
  for (double s : step_seconds) ours_total += s;
  std::sort(step_seconds.begin(), step_seconds.end());
  const double ours_fps = double(step_seconds.size()) / ours_total;

  // PCL GICP on the first consecutive pairs.
  const std::size_t pairs = std::min<std::size_t>(std::size_t(pcl_pairs), frames.size() - 1);
  std::vector<double> gicp_seconds;
  std::size_t target_points = 0;
  for (std::size_t i = 0; i < pairs; ++i) {
    const auto start = Clock::now();
    pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ> gicp;
    gicp.setMaxCorrespondenceDistance(1.0);
    gicp.setMaximumIterations(50);
    gicp.setTransformationEpsilon(1e-10);
    const PointCloud::Ptr target = downsampledCloud(frames[i], voxel_m);
    gicp.setInputTarget(target);
    gicp.setInputSource(downsampledCloud(frames[i + 1], voxel_m));
    PointCloud aligned;
    gicp.align(aligned);
    gicp_seconds.push_back(secondsSince(start));
    target_points += target->size();
  }
  double gicp_total = 0.0;
  for (double s : gicp_seconds) gicp_total += s;
  std::sort(gicp_seconds.begin(), gicp_seconds.end());
  const double gicp_fps = double(gicp_seconds.size()) / gicp_total;

  std::printf("%-34s %6zu steps  median %8.2f ms  %8.1f frames/s\n", "LidarOdometry::process", step_seconds.size(),
              step_seconds[step_seconds.size() / 2] * 1e3, ours_fps);
  std::printf("%-34s %6zu pairs  median %8.2f ms  %8.1f frames/s  (voxel %.2f m, %.0f target points)\n",
              "PCL GICP", gicp_seconds.size(), gicp_seconds[gicp_seconds.size() / 2] * 1e3, gicp_fps, voxel_m,
              double(target_points) / double(pairs));
  std::printf("ratio ours / PCL GICP: %.1fx\n", ours_fps / gicp_fps);
  return 0;
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  try {
    return range_image_mapping::run(argc, argv);
  } catch (const std::exception& error) {
    std::fprintf(stderr, "odometry_speed_benchmark: %s\n", error.what());
    return 1;
  }
}
