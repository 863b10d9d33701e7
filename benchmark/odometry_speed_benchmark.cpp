// Frames per second of the full odometry step (registration::LidarOdometry::
// process: deskew, normals, pyramid, multi-scale ICP, next target) on 2
// threads, against PCL GICP on the same consecutive pairs in the same run
// (voxel filtering, covariances, k-d trees and alignment included, from the
// identity; PCL recomputes the target each pair, as its API requires).
//
// On a shared machine wall time depends on the other jobs; the process CPU
// time per step (all threads) is reported as well.
//
// Usage: odometry_speed_benchmark [SIMULATED_DIR | lb_n3] [pcl_pairs=20 (0: none)] [voxel_m=0.2] [threads=2]
//   SIMULATED_DIR  a `rim simulate` Ouster directory (metadata.json, capture.pcap)
//   lb_n3          the real 128 x 1024 recording in the data directory (default)
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/registration/lidar_odometry.h"
#include "machine_info.h"
#include "pcl_clouds.h"
#include "test_data.h"

#include <pcl/point_types.h>
#include <pcl/registration/gicp.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using Clock = std::chrono::steady_clock;
using PointCloud = pcl::PointCloud<pcl::PointXYZ>;
constexpr int kDefaultThreads = 2;

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

using benchmark_support::processCpuSeconds;

using benchmark_support::downsampledCloud;

int run(int argc, char** argv) {
  const std::string source = argc > 1 ? argv[1] : "lb_n3";
  const int pcl_pairs = argc > 2 ? std::atoi(argv[2]) : 20;
  const double voxel_m = argc > 3 ? std::atof(argv[3]) : 0.2;
  const int threads_used = argc > 4 ? std::atoi(argv[4]) : kDefaultThreads;
  if (pcl_pairs < 0 || !(voxel_m > 0.0) || threads_used < 1) {
    std::fprintf(stderr, "pcl_pairs must be >= 0 (0: no PCL), threads >= 1 and voxel_m > 0\n");
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

  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, threads_used);
  std::printf("%s: %zu scans %d x %d, %d threads\n", source.c_str(), frames.size(), frames[0].rows(),
              frames[0].columns(), threads_used);

  // Odometry over the whole sequence: a first pass warms caches and sizes the
  // buffers, the next ones are timed (steady state, no allocation), as many
  // as give at least kMinSteps registrations (lb_n3 has only 3 scans).
  constexpr std::size_t kMinSteps = 60;
  registration::LidarOdometry odometry;
  for (const RangeImage& frame : frames) odometry.process(frame);
  std::vector<double> step_seconds;
  double step_cpu_seconds = 0.0;
  while (step_seconds.size() < kMinSteps) {
    odometry.reset();
    for (std::size_t i = 0; i < frames.size(); ++i) {
      const auto start = Clock::now();
      const double cpu_start = processCpuSeconds();
      odometry.process(frames[i]);
      // The first step of a run only builds the target: not a registration.
      if (i == 0) continue;
      step_seconds.push_back(secondsSince(start));
      step_cpu_seconds += processCpuSeconds() - cpu_start;
    }
  }
  const double ours_cpu_per_step = step_cpu_seconds / double(step_seconds.size());
  double ours_total = 0.0;
  for (double s : step_seconds) ours_total += s;
  std::sort(step_seconds.begin(), step_seconds.end());
  const double ours_fps = double(step_seconds.size()) / ours_total;

  std::printf("%-34s %6zu steps  median %8.2f ms  %8.1f frames/s  CPU %8.2f ms/step\n", "LidarOdometry::process",
              step_seconds.size(), step_seconds[step_seconds.size() / 2] * 1e3, ours_fps, ours_cpu_per_step * 1e3);
  if (pcl_pairs == 0) return 0;

  // PCL GICP on the first consecutive pairs.
  const std::size_t pairs = std::min<std::size_t>(std::size_t(pcl_pairs), frames.size() - 1);
  std::vector<double> gicp_seconds;
  std::size_t target_points = 0;
  const double gicp_cpu_start = processCpuSeconds();
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
  const double gicp_cpu_per_pair = (processCpuSeconds() - gicp_cpu_start) / double(pairs);
  double gicp_total = 0.0;
  for (double s : gicp_seconds) gicp_total += s;
  std::sort(gicp_seconds.begin(), gicp_seconds.end());
  const double gicp_fps = double(gicp_seconds.size()) / gicp_total;

  std::printf("%-34s %6zu pairs  median %8.2f ms  %8.1f frames/s  CPU %8.2f ms/pair  (voxel %.2f m, %.0f target points)\n",
              "PCL GICP", gicp_seconds.size(), gicp_seconds[gicp_seconds.size() / 2] * 1e3, gicp_fps,
              gicp_cpu_per_pair * 1e3, voxel_m, double(target_points) / double(pairs));
  std::printf("ratio ours / PCL GICP: %.1fx (wall), %.1fx (CPU)\n", ours_fps / gicp_fps,
              gicp_cpu_per_pair / ours_cpu_per_step);
  return 0;
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  using range_image_mapping::benchmark_support::runReportingErrors;
  return runReportingErrors("odometry_speed_benchmark", range_image_mapping::run, argc, argv);
}
