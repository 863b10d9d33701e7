// What several subcommands share: the odometry and mapping options on the
// command line, and the files they write (pose files, the per-frame CSV,
// meshes, JSON reports), so rim odometry, rim map and rim run agree.
#pragma once

#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/io/recording.h"
#include "range_image_mapping/mapping/tsdf_map.h"
#include "range_image_mapping/registration/lidar_odometry.h"

#include "command_line.h"

#include <json/json.h>

#include <fstream>
#include <string>
#include <vector>

namespace range_image_mapping::tool {

double median(std::vector<double> values);
// traj.txt -> traj_<suffix>
std::string siblingPath(const std::string& output, const std::string& suffix);
// Pretty JSON; creates the folder; throws naming the file when it cannot write.
void writeJsonFile(const std::string& path, const Json::Value& value);

// The recording to read (rim odometry, rim map, rim run, rim decode): the
// positional input, --metadata, --kitti, --sensor, --topic and --frames.
constexpr const char* kRecordingInputHelp =
    "an Ouster pcap (with --metadata), a ROS 1 bag (Ouster packets or PointCloud2), a folder of .bin, .pcd or "
    ".ply scans (or one scan), a KITTI velodyne folder, or a folder from rim simulate";
void addRecordingOptions(Command& command, io::RecordingOptions& recording, const std::string& input_help,
                         const std::string& frames_help);
// Says once, on stderr, what the recording's sensor model is and how well it
// explains the first clouds, with the warning when it explains too little.
void reportSensorModel(const io::Recording& recording);
// What reading the recording lost (scans that could not be read and were
// skipped, packets dropped, scans missing columns, an early end at damage):
// says it once on stderr as a warning naming the loss and what to check, and
// returns it as JSON for the command's summary or report ("warning": "" when
// nothing was lost).
Json::Value reportReading(const io::RecordingStatistics& reading);

// Odometry settings on the command line (rim odometry, rim run).
struct OdometryCommandLine {
  bool no_deskew = false;
  int deskew_passes = registration::OdometryOptions().deskew_passes;
  double kernel_scale_m = 0.5;
  double max_correspondence_distance_m = registration::RegistrationOptions().max_correspondence_distance_m;
  double moving_margin_m = registration::OdometryOptions().moving_margin_m;
  double area_weight_max_range_m = registration::RegistrationOptions().area_weight_max_range_m;
  int model_keyframes = int(registration::LocalModelOptions().keyframes);
  double keyframe_distance_m = registration::LocalModelOptions().keyframe_distance_m;
  double keyframe_angle_deg = registration::LocalModelOptions().keyframe_angle_rad * 180.0 / M_PI;
  double keyframe_range_share = registration::LocalModelOptions().keyframe_range_share;
  double max_keyframe_distance_m = registration::LocalModelOptions().max_keyframe_distance_m;
  double model_normal_radius_m = registration::LocalModelOptions().normal_radius_m;
  registration::OdometryOptions options() const;
  // With the recording's sensor, also the values in force with it (the
  // area weight's cap, the least keyframe distance), which sparse rows change.
  Json::Value json(const LidarModel* sensor = nullptr) const;
};
void addOdometryOptions(Command& command, OdometryCommandLine& odometry);

// Mapping settings on the command line (rim map, rim run), into the core's options.
void addMapOptions(Command& command, mapping::TsdfMapOptions& map);
Json::Value mapOptionsJson(const mapping::TsdfMapOptions& map, bool deskew);

// The odometry's health over a run (rim odometry, rim run): counts and the
// mean per-scan figures, for the summary line and the JSON report.
class OdometryHealth {
 public:
  void add(const registration::OdometryUpdate& update);
  int frames() const { return frames_; }
  int degenerate() const { return degenerate_; }
  // Most scans degenerate or skipped: the trajectory is not a measurement.
  bool failed() const;
  int resets() const { return resets_; }
  int skipped() const { return skipped_; }
  Json::Value json() const;
  // "N degenerate (U untrusted), S suspect, R resets, K skipped; pixels paired
  // P %, moving M % (most X %); coarse levels passed over in C scans (every
  // one in A); F keyframes D m apart"
  std::string line() const;
  // A warning naming the problem when the run looks wrong ("" if not).
  std::string warning() const;

 private:
  int frames_ = 0, registered_ = 0, degenerate_ = 0, untrusted_ = 0, suspect_ = 0, resets_ = 0, skipped_ = 0;
  double inlier_share_ = 0.0, moving_share_ = 0.0, most_moving_share_ = 0.0, prior_difference_m_ = 0.0;
  int keyframes_ = 0;
  int levels_passed_over_ = 0, every_coarse_level_passed_over_ = 0;  // scans with any, with all
  double keyframe_distance_m_ = 0.0;  // sum over registered scans of the distance in force
};

// Prints the health warning, if any, to stderr; the exit status: 3 when
// most scans were degenerate (the outputs are written, but the trajectory is
// not a measurement), else 0.
int reportHealth(const OdometryHealth& health);

// One row per odometry step: time, cost, inliers, why a scan was not used.
class OdometryFramesCsv {
 public:
  explicit OdometryFramesCsv(const std::string& path);  // throws when it cannot write
  void add(int frame, const registration::OdometryUpdate& update);
  void close();  // throws when the file could not be written

 private:
  std::string path_;
  std::ofstream file_;
};

// KITTI poses (with their times file and sidecar) at kitti_path and TUM poses
// at <stem>_tum.txt, in the odom world: of the images' own frame, or of the
// Ouster sensor frame when sensor_frame. Returns the TUM path.
std::string writeTrajectory(const std::string& kitti_path, const std::vector<io::StampedPose>& poses,
                            const io::Recording& recording, bool sensor_frame, const std::string& comment);

// Writes next to the destination and renames, so a failed run never leaves a
// truncated mesh under the name asked for.
void writeMeshAtomically(const std::string& path, const TriangleMesh& mesh);

// A mesh file against a ground-truth surface at 3 voxels (the paper's
// threshold), samples at a quarter of it: the JSON report and its summary line.
struct SurfaceEvaluation {
  Json::Value json;
  std::string summary_line;
  double f_score = 0.0;
};
SurfaceEvaluation evaluateMeshFile(const std::string& mesh_path, const std::string& truth_path, double voxel_m);
// The same with the ground truth restricted to samples within range_m of a
// sensor position (what a map clipped at range_m can hold).
SurfaceEvaluation evaluateMeshFileWithinRange(const std::string& mesh_path, const std::string& truth_path,
                                              double voxel_m, const std::vector<Eigen::Vector3f>& sensor_positions,
                                              double range_m);

}  // namespace range_image_mapping::tool
