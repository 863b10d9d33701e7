// The paper's pairwise experiment (Fig. 6): pairs of scans of a simulated
// sequence (`rim simulate --out DIR`) at frame distances 1..10, each
// registered from the identity by
//   single-scale  projective ICP at full resolution only (50 iterations)
//   multi-scale   projective ICP, default pyramid {4, 2, 1} (the paper's)
//   multi-scale wide  the same with two coarser levels, {16, 8, 4, 2, 1}: with
//                 the gate growing with the stride, the stride-16 level
//                 accepts pairs 16 m apart and captures motions of metres
//   PCL ICP       pcl::IterativeClosestPointWithNormals (point-to-plane), our
//                 normals, voxel-downsampled clouds
//   PCL GICP      pcl::GeneralizedIterativeClosestPoint, voxel-downsampled clouds
// and compared with the ground truth relative pose. Prints median and
// quartiles per method and distance, time per pair, and checks the paper's
// claim for both multi-scale pyramids; writes DIR/pairwise_registration.json
// and one box plot per method.
//
// Usage: pairwise_registration_benchmark DIR [pairs_per_distance=10] [voxel_m=auto] [seed=1]
#include "range_image_mapping/evaluation/report.h"
#include "range_image_mapping/evaluation/trajectory_metrics.h"
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/registration/projective_icp.h"

#include <pcl/filters/voxel_grid.h>
#include <pcl/point_types.h>
#include <pcl/registration/gicp.h>
#include <pcl/registration/icp.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using Clock = std::chrono::steady_clock;
constexpr int kThreads = 2;
constexpr int kMaxFrameDistance = 10;
constexpr double kCorrespondenceDistance = 1.0;
constexpr int kMaxIterations = 50;

using PointNormalCloud = pcl::PointCloud<pcl::PointNormal>;
using PointCloud = pcl::PointCloud<pcl::PointXYZ>;

// Valid points with normals of a range image, voxel-downsampled (normals averaged, renormalised).
PointNormalCloud::Ptr downsampledCloudWithNormals(const RangeImage& image, double voxel_m) {
  registration::VertexNormalMap map;
  computeVertexNormalMap(image, 1, {}, map);
  PointNormalCloud::Ptr cloud(new PointNormalCloud);
  for (std::size_t i = 0; i < map.points.size(); ++i) {
    if (!std::isfinite(map.normals[i].x())) continue;
    pcl::PointNormal point;
    point.getVector3fMap() = map.points[i];
    point.getNormalVector3fMap() = map.normals[i];
    cloud->push_back(point);
  }
  PointNormalCloud::Ptr downsampled(new PointNormalCloud);
  pcl::VoxelGrid<pcl::PointNormal> grid;
  grid.setLeafSize(float(voxel_m), float(voxel_m), float(voxel_m));
  grid.setDownsampleAllData(true);
  grid.setInputCloud(cloud);
  grid.filter(*downsampled);
  for (pcl::PointNormal& point : *downsampled) point.getNormalVector3fMap().normalize();
  return downsampled;
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

struct Method {
  std::string name;
  // T_target_source from the identity guess, all preprocessing included.
  std::function<Eigen::Isometry3d(const RangeImage& target, const RangeImage& source)> registerPair;
  evaluation::TrajectoryEvaluation errors;  // only `pairwise` is filled (for plotPairwiseErrors)
  std::vector<double> seconds;              // per pair
};

Eigen::Isometry3d projectiveRegistration(registration::ProjectiveIcp& icp, const RangeImage& target,
                                         const RangeImage& source) {
  icp.setTarget(target);
  return icp.align(source, Eigen::Isometry3d::Identity()).target_from_source;
}

std::string statisticsJson(const evaluation::ErrorStatistics& s) {
  char text[256];
  std::snprintf(text, sizeof text,
                "{\"count\": %zu, \"q1\": %.6g, \"median\": %.6g, \"q3\": %.6g, \"mean\": %.6g, \"max\": %.6g}",
                s.count, s.first_quartile, s.median, s.third_quartile, s.mean, s.maximum);
  return text;
}

int run(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s SIMULATED_DIR [pairs_per_distance=10] [voxel_m=auto] [seed=1]\n", argv[0]);
    return 2;
  }
  const std::string directory = argv[1];
  const int pairs_per_distance = argc > 2 ? std::atoi(argv[2]) : 10;
  double voxel_m = argc > 3 ? std::atof(argv[3]) : 0.0;
  const unsigned seed = argc > 4 ? unsigned(std::atoi(argv[4])) : 1u;
  if (pairs_per_distance < 1) {
    std::fprintf(stderr, "pairs_per_distance must be at least 1, got '%s'\n", argv[2]);
    return 2;
  }

  const OusterMetadata metadata = loadOusterMetadata(directory + "/metadata.json");
  const std::vector<RangeImage> frames = io::readOusterRangeImages(directory + "/capture.pcap", metadata);
  const std::vector<io::StampedPose> poses = io::readPoseFile(directory + "/poses_tum.txt");
  if (frames.size() != poses.size()) {
    std::fprintf(stderr, "%s: %zu scans decoded but %zu ground-truth poses\n", directory.c_str(), frames.size(),
                 poses.size());
    return 1;
  }
  if (int(frames.size()) <= kMaxFrameDistance) {
    std::fprintf(stderr, "%s: %zu scans, need more than %d\n", directory.c_str(), frames.size(), kMaxFrameDistance);
    return 1;
  }
  // Mean range decides indoor vs outdoor voxel size (0.1 m / 0.2 m) unless given.
  if (voxel_m <= 0.0) {
    double sum = 0.0;
    std::size_t count = 0;
    for (float range : frames[0].range)
      if (isValidRange(range)) sum += range, ++count;
    voxel_m = count > 0 && sum / double(count) < 10.0 ? 0.1 : 0.2;
  }

  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, kThreads);
  registration::RegistrationOptions single_options;
  single_options.strides = {1};
  single_options.iterations = {kMaxIterations};
  registration::RegistrationOptions wide_options;
  wide_options.strides = {16, 8, 4, 2, 1};
  wide_options.iterations = {20, 20, 20, 20, 10};
  registration::ProjectiveIcp single_scale(single_options), multi_scale, multi_scale_wide(wide_options);

  std::vector<Method> methods;
  methods.push_back({"single-scale", [&](const RangeImage& t, const RangeImage& s) {
                       return projectiveRegistration(single_scale, t, s);
                     }});
  methods.push_back({"multi-scale", [&](const RangeImage& t, const RangeImage& s) {
                       return projectiveRegistration(multi_scale, t, s);
                     }});
  methods.push_back({"multi-scale wide", [&](const RangeImage& t, const RangeImage& s) {
                       return projectiveRegistration(multi_scale_wide, t, s);
                     }});
  methods.push_back({"PCL ICP", [&](const RangeImage& t, const RangeImage& s) {
                       pcl::IterativeClosestPointWithNormals<pcl::PointNormal, pcl::PointNormal, double> icp;
                       icp.setMaxCorrespondenceDistance(kCorrespondenceDistance);
                       icp.setMaximumIterations(kMaxIterations);
                       icp.setTransformationEpsilon(1e-10);
                       icp.setInputTarget(downsampledCloudWithNormals(t, voxel_m));
                       icp.setInputSource(downsampledCloudWithNormals(s, voxel_m));
                       PointNormalCloud aligned;
                       icp.align(aligned);
                       return Eigen::Isometry3d(icp.getFinalTransformation());
                     }});
  methods.push_back({"PCL GICP", [&](const RangeImage& t, const RangeImage& s) {
                       pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ> gicp;
                       gicp.setMaxCorrespondenceDistance(kCorrespondenceDistance);
                       gicp.setMaximumIterations(kMaxIterations);
                       gicp.setTransformationEpsilon(1e-10);
                       gicp.setInputTarget(downsampledCloud(t, voxel_m));
                       gicp.setInputSource(downsampledCloud(s, voxel_m));
                       PointCloud aligned;
                       gicp.align(aligned);
                       return Eigen::Isometry3d(gicp.getFinalTransformation().cast<double>());
                     }});

  std::printf("%s: %zu scans %d x %d, %d pairs per distance 1..%d (seed %u), voxel %.2f m, %d threads\n",
              directory.c_str(), frames.size(), frames[0].rows(), frames[0].columns(), pairs_per_distance,
              kMaxFrameDistance, seed, voxel_m, kThreads);
  std::mt19937 random(seed);
  for (int distance = 1; distance <= kMaxFrameDistance; ++distance) {
    std::uniform_int_distribution<std::size_t> first_frame(0, frames.size() - 1 - distance);
    std::vector<std::size_t> firsts;
    for (int k = 0; k < pairs_per_distance; ++k) firsts.push_back(first_frame(random));
    for (Method& method : methods) {
      evaluation::PairwiseErrors errors;
      errors.frame_distance = distance;
      errors.first_frames = firsts;
      for (std::size_t i : firsts) {
        const std::size_t j = i + distance;
        const Eigen::Isometry3d truth = poses[i].pose.inverse() * poses[j].pose;  // T_i_j
        const auto start = Clock::now();
        const Eigen::Isometry3d estimate = method.registerPair(frames[i], frames[j]);
        method.seconds.push_back(std::chrono::duration<double>(Clock::now() - start).count());
        errors.rotation_deg.push_back(evaluation::rotationAngle(estimate.linear() * truth.linear().transpose()) *
                                      180.0 / M_PI);
        errors.translation_m.push_back((estimate.translation() - truth.translation()).norm());
      }
      errors.rotation_statistics = evaluation::summarize(errors.rotation_deg);
      errors.translation_statistics = evaluation::summarize(errors.translation_m);
      method.errors.pairwise.push_back(std::move(errors));
    }
    std::fprintf(stderr, "distance %d done\n", distance);
  }

  // Tables: median [q1, q3] per method.
  std::printf("\nrotation error, deg: median [q1, q3]\n%4s", "d");
  for (const Method& method : methods) std::printf(" %30s", method.name.c_str());
  for (int d = 0; d < kMaxFrameDistance; ++d) {
    std::printf("\n%4d", d + 1);
    for (const Method& method : methods) {
      const auto& s = method.errors.pairwise[d].rotation_statistics;
      std::printf("    %8.4f [%8.4f, %8.4f]", s.median, s.first_quartile, s.third_quartile);
    }
  }
  std::printf("\n\ntranslation error, m: median [q1, q3]\n%4s", "d");
  for (const Method& method : methods) std::printf(" %30s", method.name.c_str());
  for (int d = 0; d < kMaxFrameDistance; ++d) {
    std::printf("\n%4d", d + 1);
    for (const Method& method : methods) {
      const auto& s = method.errors.pairwise[d].translation_statistics;
      std::printf("    %8.4f [%8.4f, %8.4f]", s.median, s.first_quartile, s.third_quartile);
    }
  }
  std::printf("\n\ntime per pair, ms: median (mean)\n");
  for (const Method& method : methods) {
    const evaluation::ErrorStatistics s = evaluation::summarize(method.seconds);
    std::printf("%-17s %9.1f (%9.1f)\n", method.name.c_str(), s.median * 1e3, s.mean * 1e3);
  }

  // The paper's claim. Medians are compared; differences below 1 mm / 0.001 deg count as ties.
  std::printf("\nclaim: multi-scale at least as accurate as both PCL baselines at every distance (median\n"
              "rotation and translation errors not larger, ties within 1 mm / 0.001 deg), and better\n"
              "(both medians strictly smaller) at distances >= 5\n");
  bool all_pass = true;
  for (int m : {1, 2}) {
    const Method& ours = methods[m];
    std::printf("%s:\n", ours.name.c_str());
    bool method_pass = true;
    for (int d = 0; d < kMaxFrameDistance; ++d) {
      const auto& o = ours.errors.pairwise[d];
      bool at_least_as_good = true, better = true;
      for (int b : {3, 4}) {
        const auto& p = methods[b].errors.pairwise[d];
        const double dr = o.rotation_statistics.median - p.rotation_statistics.median;
        const double dt = o.translation_statistics.median - p.translation_statistics.median;
        at_least_as_good = at_least_as_good && dr <= 1e-3 && dt <= 1e-3;
        better = better && dr < -1e-3 && dt < -1e-3;
      }
      const bool pass = at_least_as_good && (d + 1 < 5 || better);
      method_pass = method_pass && pass;
      std::printf("  distance %2d: %s (at least as accurate: %s, better: %s)\n", d + 1, pass ? "PASS" : "FAIL",
                  at_least_as_good ? "yes" : "no", better ? "yes" : "no");
    }
    std::printf("  %s: %s\n", ours.name.c_str(), method_pass ? "PASS" : "FAIL");
    all_pass = all_pass && method_pass;
  }
  std::printf("overall (both pyramids): %s\n", all_pass ? "PASS" : "FAIL");

  // JSON and plots.
  const std::string json_path = directory + "/pairwise_registration.json";
  std::ofstream json(json_path);
  json << "{\n  \"sequence\": \"" << directory << "\",\n  \"pairs_per_distance\": " << pairs_per_distance
       << ",\n  \"seed\": " << seed << ",\n  \"voxel_m\": " << voxel_m << ",\n  \"claim_pass\": "
       << (all_pass ? "true" : "false") << ",\n  \"methods\": [";
  for (std::size_t m = 0; m < methods.size(); ++m) {
    const Method& method = methods[m];
    json << (m ? "," : "") << "\n    {\"name\": \"" << method.name << "\", \"seconds_per_pair\": "
         << statisticsJson(evaluation::summarize(method.seconds)) << ", \"distances\": [";
    for (std::size_t d = 0; d < method.errors.pairwise.size(); ++d) {
      const auto& e = method.errors.pairwise[d];
      json << (d ? "," : "") << "\n      {\"frame_distance\": " << e.frame_distance
           << ", \"rotation_deg\": " << statisticsJson(e.rotation_statistics)
           << ", \"translation_m\": " << statisticsJson(e.translation_statistics) << "}";
    }
    json << "]}";
  }
  json << "\n  ]\n}\n";
  std::printf("wrote %s\n", json_path.c_str());
  for (const Method& method : methods) {
    std::string file = method.name;
    std::replace(file.begin(), file.end(), ' ', '_');
    const std::string png = directory + "/pairwise_" + file + ".png";
    try {
      evaluation::plotPairwiseErrors(method.errors, png);
      std::printf("wrote %s\n", png.c_str());
    } catch (const evaluation::PlotError& error) {
      std::printf("no plot for %s: %s\n", method.name.c_str(), error.what());
    }
  }
  return 0;
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  try {
    return range_image_mapping::run(argc, argv);
  } catch (const std::exception& error) {
    std::fprintf(stderr, "pairwise_registration_benchmark: %s\n", error.what());
    return 1;
  }
}
