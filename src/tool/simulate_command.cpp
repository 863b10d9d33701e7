// rim simulate: a spinning LiDAR driven through a mesh scene, written as the
// real sensor's data (pcap, bags, KITTI folders) with exact ground truth.
#include "commands.h"
#include "progress.h"

#include "range_image_mapping/io/actor_tracks.h"
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/mesh_file.h"
#include "range_image_mapping/io/pcd.h"
#include "range_image_mapping/io/pcap_writer.h"
#include "range_image_mapping/io/ply.h"
#include "range_image_mapping/io/png.h"
#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/ouster_packet_encoder.h"
#include "range_image_mapping/sensor_catalog.h"
#include "range_image_mapping/simulation/lidar_simulator.h"
#include "range_image_mapping/simulation/scene_generator.h"
#include "range_image_mapping/simulation/sensor_presets.h"
#include "range_image_mapping/simulation/surface_sampler.h"
#include "range_image_mapping/simulation/traffic.h"
#ifdef RIM_WITH_ROSBAG
#include "range_image_mapping/ros/bag_writer.h"
#endif

#include <json/json.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <set>
#include <sstream>

namespace range_image_mapping::tool {
namespace {

using simulation::MotionProfile;
using simulation::SceneKind;

struct Preset {
  const char* name;
  const char* scene;   // indoor, outdoor or traffic
  const char* sensor;  // OS-0-128, OS-1-128, hdl64 or a catalog name
  const char* motion;  // car, cart, handheld or traffic
  int frames;
  const char* formats;
};

// traffic: stop-and-go between two trucks, with moving actors (their tracks in
// actors.txt, per-pixel labels in labels/).
const Preset kPresets[] = {
    {"outdoor_car", "outdoor", "OS-1-128", "car", 300, "pcap"},
    {"indoor_cart", "indoor", "OS-0-128", "cart", 300, "pcap"},
    {"handheld_fast", "indoor", "OS-0-128", "handheld", 150, "pcap"},
    {"kitti_like", "outdoor", "hdl64", "car", 300, "kitti"},
    {"traffic", "traffic", "OS-1-128", "traffic", 300, "pcap"},
    {"traffic_hdl64", "traffic", "hdl64", "traffic", 300, "kitti"},
    // The drivers' sensors as a user records them: a folder of plain clouds.
    {"outdoor_vlp16", "outdoor", "VLP-16", "car", 300, "pcd"},
    {"outdoor_vlp32c", "outdoor", "VLP-32C", "car", 300, "pcd"},
    {"outdoor_hdl32", "outdoor", "HDL-32E", "car", 300, "pcd"},
    {"outdoor_pandar64", "outdoor", "Pandar64", "car", 300, "pcd"},
};

// The real sensors' metadata in the shared data folder are the defaults; the
// built-in approximations stand in where that folder is absent.
const char* realMetadataFile(const std::string& product) {
  if (product == "OS-0-128") return "ouster-pcaps/OS-0-128-U1_v2.3.0_1024x10.json";
  if (product == "OS-1-128") return "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json";
  return nullptr;
}

std::string dataDirectory() {
  if (const char* directory = std::getenv("RIM_DATA_DIR")) return directory;
  return RIM_DEFAULT_DATA_DIR;
}

struct SimulateOptions {
  std::string preset;
  std::string output_directory;
  int frames = 0;  // 0: the preset's
  uint32_t seed = 1;
  std::string sensor;   // metadata JSON, OS-0-128, OS-1-128, hdl64 or a catalog name (default: the preset's)
  std::string scene;    // indoor, outdoor, traffic or a PLY/OBJ mesh (default: the preset's)
  std::string motion;   // car, cart, handheld, traffic or a pose file (default: the preset's)
  bool no_actors = false;  // the traffic scene without its moving actors
  std::string formats;  // comma-separated: pcap, bag, points-bag, kitti, pcd (default: the preset's)
  std::string profile = "RNG19_RFL8_SIG16_NIR16";
  std::string cloud_layout = "organized";
  double noise_sigma_m = 0.01;
  double dropout = 0.0;
  double min_range_m = 0.3;
  double max_range_m = 120.0;
  double divergence_rad = 0.0;
  bool no_motion_distortion = false;
  double surface_spacing_m = 0.0;  // 0: 2 cm indoors, 7.5 cm outdoors (a 300 m drive sees ~50000 m2)
  // Only hits this close count as seen (0: all): the ground truth of a map
  // clipped at this range.
  double surface_max_range_m = 0.0;
  double seen_distance_m = 0.0;  // 0: the sample spacing, at least 2 cm
  double start_time_s = 1.0;
};

struct Sensor {
  LidarModelConstPtr model;
  std::optional<OusterMetadata> ouster;  // absent for the synthetic HDL-64 and the catalog's sensors
  std::string frame;                     // os_lidar, velodyne (KITTI) or lidar (a folder of clouds)
  bool kitti = false;                    // KITTI's HDL-64E: its .bin folder reads back with this model
};

// A metadata file whose UDP profile is replaced: the simulated packets are in
// that profile, so the metadata written next to them must say so.
std::string withUdpProfile(const std::string& json_text, UdpProfile profile) {
  Json::Value root;
  std::istringstream stream(json_text);
  std::string errors;
  if (!Json::parseFromStream(Json::CharReaderBuilder(), stream, &root, &errors))
    throw std::invalid_argument("metadata: not valid JSON: " + errors);
  const char* name = toString(profile);
  if (root.isMember("lidar_data_format")) {  // nested format
    root["lidar_data_format"]["udp_profile_lidar"] = name;
    root["config_params"]["udp_profile_lidar"] = name;
  } else {
    root["data_format"]["udp_profile_lidar"] = name;
  }
  Json::StreamWriterBuilder writer;
  writer["indentation"] = "  ";
  return Json::writeString(writer, root);
}

Sensor makeSensor(const std::string& choice, UdpProfile profile) {
  Sensor sensor;
  if (const std::optional<LidarIntrinsics> named = catalogSensor(choice);
      named && !std::filesystem::exists(choice)) {
    sensor.kitti = named->sensor_model == kittiHdl64Intrinsics().sensor_model;
    sensor.model = std::make_shared<const LidarModel>(*named);
    sensor.frame = sensor.kitti ? "velodyne" : "lidar";
    return sensor;
  }
  std::string json;
  if (std::filesystem::exists(choice)) {
    std::ifstream file(choice);
    json.assign(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
  } else if (const char* relative = realMetadataFile(choice);
             relative && !dataDirectory().empty() &&
             std::filesystem::exists(std::filesystem::path(dataDirectory()) / relative)) {
    std::ifstream file(std::filesystem::path(dataDirectory()) / relative);
    json.assign(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
  } else if (choice == "OS-0-128" || choice == "OS-1-128") {
    std::cerr << "note: no real " << choice << " metadata at " << dataDirectory() << "/"
              << (relative ? relative : "") << " (set RIM_DATA_DIR); using the built-in approximation of its beam tables\n";
    json = simulation::ousterLikeMetadataJson(choice, profile);
  } else {
    throw std::invalid_argument("--sensor " + choice +
                                ": neither a metadata file nor one of OS-0-128, OS-1-128, " + sensorCatalogNames());
  }
  sensor.ouster = parseOusterMetadata(withUdpProfile(json, profile));
  sensor.model = std::make_shared<const LidarModel>(sensor.ouster->intrinsics);
  sensor.frame = "os_lidar";
  return sensor;
}

std::set<std::string> parseFormats(const std::string& text, const Sensor& sensor) {
  std::set<std::string> formats;
  std::stringstream stream(text);
  for (std::string format; std::getline(stream, format, ',');) {
    if (format.empty()) continue;
    if (format != "pcap" && format != "bag" && format != "points-bag" && format != "kitti" && format != "pcd")
      throw std::invalid_argument("--formats: unknown format '" + format +
                                  "' (known: pcap, bag, points-bag, kitti, pcd)");
    if ((format == "pcap" || format == "bag") && !sensor.ouster)
      throw std::invalid_argument("--formats " + format + " needs an Ouster sensor, not " +
                                  sensor.model->intrinsics().sensor_model);
    // A KITTI velodyne folder reads back as KITTI's HDL-64E, whatever made it.
    if (format == "kitti" && !sensor.kitti)
      throw std::invalid_argument("--formats kitti: a KITTI velodyne folder is read as KITTI's HDL-64E, not " +
                                  sensor.model->intrinsics().sensor_model +
                                  "; write --formats pcd (a folder of clouds whose model rim estimates)");
#ifndef RIM_WITH_ROSBAG
    if (format == "bag" || format == "points-bag")
      throw std::invalid_argument("--formats " + format +
                                  ": this rim was built without ROS (RIM_CORE_ONLY); bags need the catkin build");
#endif
    formats.insert(format);
  }
  return formats;
}

// A scan as a driver's plain cloud: the returns in the lidar frame, row by
// row, with intensity (0..1), each point's firing time after the scan's first
// column (velodyne_pointcloud's relative `time`) and its actor label.
struct ScanPoints {
  PointCloudInput cloud;
  std::vector<uint32_t> labels;
};

ScanPoints scanPoints(const simulation::SimulatedScan& scan, const LidarModel& model) {
  ScanPoints points;
  PointCloudInput& cloud = points.cloud;
  const std::vector<uint64_t>& column_ns = scan.raw.timestamp_ns;
  for (int v = 0; v < model.rows(); ++v)
    for (int u = 0; u < model.columns(); ++u)
      if (scan.image.valid(v, u)) {
        cloud.points.push_back(model.unproject(u, v, scan.image.at(v, u)));
        cloud.intensity.push_back(scan.image.intensity.empty() ? 0.0f
                                                               : scan.image.intensity[scan.image.index(v, u)] / 255.0f);
        cloud.time_offset_s.push_back(static_cast<float>(double(column_ns[u] - column_ns.front()) * 1e-9));
        points.labels.push_back(scan.true_actor[static_cast<std::size_t>(v) * model.columns() + u]);
      }
  return points;
}

int runSimulate(SimulateOptions options) {
  const Preset* preset = nullptr;
  for (const Preset& candidate : kPresets)
    if (options.preset == candidate.name) preset = &candidate;
  if (!preset && (options.sensor.empty() || options.scene.empty() || options.motion.empty()))
    throw std::invalid_argument("give --preset, or all of --sensor, --scene and --motion");
  if (preset) {
    // Another sensor than the preset's gets that sensor's own default formats.
    if (options.formats.empty() && (options.sensor.empty() || options.sensor == preset->sensor))
      options.formats = preset->formats;
    if (options.sensor.empty()) options.sensor = preset->sensor;
    if (options.motion.empty()) options.motion = preset->motion;
    if (options.scene.empty()) options.scene = preset->scene;
    if (options.frames == 0) options.frames = preset->frames;
  }
  if (options.frames <= 0) options.frames = 100;

  const UdpProfile profile = udpProfileFromString(options.profile);
  const Sensor sensor = makeSensor(options.sensor, profile);
  if (options.formats.empty()) options.formats = sensor.ouster ? "pcap" : sensor.kitti ? "kitti" : "pcd";
  const std::set<std::string> formats = parseFormats(options.formats, sensor);
  if (options.cloud_layout == "ouster-ros" && !sensor.ouster)
    throw std::invalid_argument("--cloud-layout ouster-ros is the Ouster driver's cloud; " +
                                sensor.model->intrinsics().sensor_model + " is no Ouster sensor");
  const std::filesystem::path out(options.output_directory);
  std::filesystem::create_directories(out);

  // Scene and motion.
  const double frequency = sensor.ouster ? sensor.ouster->frequency_hz : 10.0;
  const double end_time = options.start_time_s + (options.frames + 1) / frequency;
  simulation::Scene scene;
  simulation::TrafficScenario traffic;
  if (options.motion == "traffic" && options.scene != "traffic")
    throw std::invalid_argument("--motion traffic is the traffic scene's own stop-and-go drive; give --scene traffic");
  if (options.scene == "traffic") {
    simulation::TrafficOptions traffic_options;
    traffic_options.seed = options.seed;
    traffic_options.duration_s = end_time + 0.5;
    traffic = simulation::makeTrafficScenario(traffic_options);
    scene = std::move(traffic.scene);
    if (options.no_actors) traffic.actors.clear();
  } else if (options.scene == "indoor" || options.scene == "outdoor") {
    simulation::SceneOptions scene_options;
    scene_options.kind = options.scene == "indoor" ? SceneKind::kIndoor : SceneKind::kOutdoor;
    scene_options.seed = options.seed;
    scene = simulation::generateScene(scene_options);
  } else {
    scene.mesh = io::loadMeshFile(options.scene);
  }
  std::unique_ptr<simulation::Trajectory> trajectory;
  if (options.motion == "traffic") {
    trajectory = std::move(traffic.ego);
  } else if (options.motion == "car" || options.motion == "cart" || options.motion == "handheld") {
    if (scene.route.size() < 3)
      throw std::invalid_argument("--motion " + options.motion +
                                  " follows a generated scene's route; with a mesh file, give a pose file");
    simulation::MotionOptions motion;
    motion.profile = options.motion == "car"    ? MotionProfile::kCar
                     : options.motion == "cart" ? MotionProfile::kCart
                                                : MotionProfile::kHandheld;
    motion.duration_s = end_time + 0.5;
    motion.seed = options.seed;
    motion.sensor_height_m = motion.profile == MotionProfile::kCar ? 1.8 : 1.2;
    trajectory = simulation::makeTrajectory(scene, motion);
  } else {
    trajectory = simulation::loadTrajectory(options.motion);
    options.start_time_s = std::max(options.start_time_s, trajectory->startTime());
  }
  if (options.start_time_s + options.frames / frequency > trajectory->endTime())
    throw std::invalid_argument("the trajectory ends at " + std::to_string(trajectory->endTime()) +
                                " s, before the last of " + std::to_string(options.frames) + " frames");

  simulation::SensorEffects effects;
  effects.range_noise_sigma_m = options.noise_sigma_m;
  effects.dropout_probability = options.dropout;
  effects.min_range_m = options.min_range_m;
  effects.max_range_m = options.max_range_m;
  effects.beam_divergence_rad = options.divergence_rad;
  effects.motion_distortion = !options.no_motion_distortion;
  if (options.surface_spacing_m <= 0.0) options.surface_spacing_m = options.scene == "indoor" ? 0.02 : 0.075;
  const simulation::RayCaster caster(scene.mesh);
  simulation::LidarSimulator simulator(sensor.model, caster, effects, options.seed, frequency);
  const std::vector<simulation::MovingActor>& actors = traffic.actors;
  simulator.setActors(&actors);

  // Outputs.
  std::unique_ptr<io::OusterPcapWriter> pcap;
  if (sensor.ouster) {
    std::ofstream(out / "metadata.json") << sensor.ouster->json;
    if (formats.count("pcap")) pcap = std::make_unique<io::OusterPcapWriter>((out / "capture.pcap").string(), *sensor.ouster);
  }
#ifdef RIM_WITH_ROSBAG
  std::unique_ptr<BagWriter> packet_bag, points_bag;
  std::unique_ptr<OusterPacketEncoder> encoder;
  // Bag times: the simulation clock from a fixed epoch (ROS time 0 means "unset").
  constexpr int64_t kBagEpochNs = 1'700'000'000'000'000'000;
  if (formats.count("bag")) {
    packet_bag = std::make_unique<BagWriter>((out / "packets.bag").string());
    encoder = std::make_unique<OusterPacketEncoder>(*sensor.ouster);
    packet_bag->writeOusterMetadata(sensor.ouster->json, kBagEpochNs);
  }
  if (formats.count("points-bag")) points_bag = std::make_unique<BagWriter>((out / "points.bag").string());
  const CloudLayout layout = options.cloud_layout == "plain"         ? CloudLayout::kPlain
                             : options.cloud_layout == "unorganized" ? CloudLayout::kUnorganized
                             : options.cloud_layout == "ouster-ros"  ? CloudLayout::kOusterRos
                             : options.cloud_layout == "velodyne"    ? CloudLayout::kVelodyne
                             : options.cloud_layout == "hesai"       ? CloudLayout::kHesai
                                                                     : CloudLayout::kOrganized;
  // The drivers' frames; ouster-ros stamps with the sensor's own clock (the
  // simulation clock: TIME_FROM_INTERNAL_OSC), the others with the host's.
  const std::string cloud_frame = layout == CloudLayout::kOusterRos  ? "os_sensor"
                                  : layout == CloudLayout::kVelodyne ? "velodyne"
                                  : layout == CloudLayout::kHesai    ? "hesai_lidar"
                                                                     : sensor.frame;
  const bool driver_layout =
      layout == CloudLayout::kOusterRos || layout == CloudLayout::kVelodyne || layout == CloudLayout::kHesai;
#endif
  if (formats.count("kitti")) std::filesystem::create_directories(out / "velodyne");
  if (formats.count("pcd")) std::filesystem::create_directories(out / "clouds");
  std::vector<double> scan_times_s;
  // Moving actors' ground truth: their poses per scan and per-pixel labels.
  std::vector<io::ActorTrack> tracks;
  for (std::size_t k = 0; k < actors.size(); ++k) {
    io::ActorTrack track;
    track.label = static_cast<int>(k + 1);
    track.kind = simulation::toString(actors[k].kind);
    track.name = actors[k].name;
    for (const simulation::ActorBox& box : actors[k].boxes) track.boxes.push_back({box.centre_m, box.half_size_m});
    tracks.push_back(std::move(track));
  }
  if (!actors.empty()) std::filesystem::create_directories(out / "labels");
  std::size_t returns = 0, actor_returns = 0, truck_returns = 0;
  io::PoseFileInfo pose_info;
  pose_info.frame = sensor.frame;
  pose_info.comment = "rim simulate, seed " + std::to_string(options.seed) + ", pose at each scan's first column";
  io::ColumnTimesWriter column_times((out / "column_times.txt").string(), pose_info);
  std::vector<io::StampedPose> poses;
  // A sample counts as seen up to (1 + sqrt 3) seen distances from a hit
  // (SeenRegion): kept below the evaluation threshold (3 voxels, 12 cm at the
  // finest preset), so recall is not charged for surface beyond what any ray
  // reached.
  simulation::SeenRegion seen(options.seen_distance_m > 0.0 ? options.seen_distance_m
                                                            : std::max(options.surface_spacing_m, 0.02));

  const auto started = std::chrono::steady_clock::now();
  simulation::SimulatedScan scan;
  for (int frame = 0; frame < options.frames; ++frame) {
    const double start = options.start_time_s + frame / frequency;
    simulator.simulate(*trajectory, start, static_cast<uint32_t>(frame), scan);
    if (sensor.ouster) quantizeForProfile(scan.raw, profile);
    poses.push_back({start, scan.column_poses.front()});
    column_times.write(scan.raw.timestamp_ns);
    // Noise-free hits, in the world: what the sensor saw.
    const LidarModel& model = *sensor.model;
    // Hits on moving actors are not seen surface: the ground truth is the static world.
    for (int v = 0; v < model.rows(); ++v)
      for (int u = 0; u < model.columns(); ++u) {
        const std::size_t pixel = static_cast<std::size_t>(v) * model.columns() + u;
        const float range = scan.true_range[pixel];
        if (std::isfinite(range) && scan.true_actor[pixel] == 0 &&
            !(options.surface_max_range_m > 0.0 && range > options.surface_max_range_m))
          seen.addHit((scan.column_poses[u] * model.unproject(u, v, range).cast<double>()).cast<float>());
      }
    if (!actors.empty()) {
      char name[32];
      std::snprintf(name, sizeof name, "%06d.png", frame);
      io::writeGrey16Png((out / "labels" / name).string(), model.columns(), model.rows(), scan.true_actor);
      for (std::size_t k = 0; k < actors.size(); ++k) {
        tracks[k].times_s.push_back(start);
        tracks[k].world_from_actor.push_back(actors[k].worldFromActor(start));
      }
      for (std::size_t pixel = 0; pixel < scan.true_actor.size(); ++pixel) {
        if (!std::isfinite(scan.true_range[pixel])) continue;
        ++returns;
        const uint16_t label = scan.true_actor[pixel];
        if (label == 0) continue;
        ++actor_returns;
        if (actors[label - 1].name == "truck_left" || actors[label - 1].name == "truck_right") ++truck_returns;
      }
    }
    if (pcap) pcap->writeScan(scan.raw);
#ifdef RIM_WITH_ROSBAG
    if (packet_bag) packet_bag->writeOusterScan(*encoder, scan.raw, kBagEpochNs);
    if (points_bag) {
      sensor_msgs::PointCloud2 cloud;
      if (driver_layout && layout != CloudLayout::kOusterRos) {
        RangeImage host_clock = scan.image;  // header stamp and absolute point times on the bag's clock
        host_clock.stamp_ns += kBagEpochNs;
        for (uint64_t& time_ns : host_clock.column_timestamp_ns)
          if (time_ns != 0) time_ns += kBagEpochNs;
        rangeImageToPointCloud2(host_clock, layout, cloud_frame, cloud);
      } else {
        rangeImageToPointCloud2(scan.image, layout, cloud_frame, cloud);
        if (!driver_layout) cloud.header.stamp.fromNSec(kBagEpochNs + static_cast<int64_t>(start * 1e9));
      }
      points_bag->writePointCloud(cloud, "/points");
    }
#endif
    scan_times_s.push_back(start);
    const ScanPoints points = scanPoints(scan, model);
    if (formats.count("pcd")) {
      char name[32];
      std::snprintf(name, sizeof name, "%06d.pcd", frame);
      io::writePcd((out / "clouds" / name).string(), points.cloud, io::PcdEncoding::kBinary);
    }
    if (formats.count("kitti")) {
      char name[32];
      std::snprintf(name, sizeof name, "%06d.bin", frame);
      const std::vector<uint32_t>& point_labels = points.labels;
      io::writeKittiVelodyne((out / "velodyne" / name).string(), points.cloud.points, points.cloud.intensity);
      if (!actors.empty()) {  // one little-endian uint32 per point of the .bin, as SemanticKITTI's .label
        std::snprintf(name, sizeof name, "%06d.label", frame);
        std::ofstream labels(out / "labels" / name, std::ios::binary);
        labels.write(reinterpret_cast<const char*>(point_labels.data()),
                     static_cast<std::streamsize>(point_labels.size() * sizeof(uint32_t)));
        if (!labels) throw std::runtime_error("cannot write " + (out / "labels" / name).string());
      }
    }
    showProgress(frame + 1, options.frames, started);
  }
  if (pcap) pcap->close();
  column_times.close();
  if (formats.count("pcd")) io::writeTimes((out / "clouds" / "times.txt").string(), scan_times_s);
#ifdef RIM_WITH_ROSBAG
  if (packet_bag) packet_bag->close();
  if (points_bag) points_bag->close();
#endif

  // Ground truth: poses in the image's own frame and, for Ouster, the sensor frame.
  io::writeKittiPosesWithTimes((out / "poses_kitti.txt").string(), poses, pose_info);
  io::writeTumPoses((out / "poses_tum.txt").string(), poses, pose_info);
  if (sensor.ouster) {
    io::PoseFileInfo sensor_info = pose_info;
    sensor_info.frame = "os_sensor";
    const auto sensor_poses = io::changePoseFrame(poses, sensor.ouster->intrinsics.lidar_to_sensor);
    io::writeKittiPosesWithTimes((out / "poses_sensor_kitti.txt").string(), sensor_poses, sensor_info);
    io::writeTumPoses((out / "poses_sensor_tum.txt").string(), sensor_poses, sensor_info);
  }
  io::saveMeshFile((out / "scene.ply").string(), scene.mesh);
  if (!actors.empty())
    io::writeActorTracks((out / "actors.txt").string(), tracks,
                         "rim simulate, seed " + std::to_string(options.seed) + ", pose at each scan's first column");
  SurfaceSampleOptions sampling;
  sampling.spacing_m = options.surface_spacing_m;
  sampling.seed = options.seed;
  const std::vector<Eigen::Vector3f> surface = simulation::sampleSeenSurface(scene.mesh, seen, sampling);
  io::writePlyPointCloud((out / "surface.ply").string(), surface);

  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  std::cout << options.frames << " frames of " << sensor.model->intrinsics().sensor_model << " ("
            << sensor.model->rows() << " x " << sensor.model->columns() << ") in " << seconds << " s; "
            << scene.mesh.triangles.size() << " scene triangles, " << surface.size()
            << " ground-truth surface samples; written to " << out.string() << "\n";
  if (formats.count("pcd"))
    std::cout << "plain clouds (no sensor model) in " << (out / "clouds").string() << ": give that folder to rim ("
              << out.string() << " itself also holds scene.ply and surface.ply)\n";
  if (!actors.empty() && returns > 0)
    std::cout << actors.size() << " moving actors: " << 100.0 * actor_returns / returns << " % of the true returns ("
              << 100.0 * truck_returns / returns << " % on the trucks alongside)\n";
  return 0;
}

}  // namespace

std::vector<std::string> simulationPresetNames() {
  std::vector<std::string> names;
  for (const Preset& preset : kPresets) names.push_back(preset.name);
  return names;
}

bool isIndoorPreset(const std::string& preset) {
  for (const Preset& candidate : kPresets)
    if (preset == candidate.name) return std::string(candidate.scene) == "indoor";
  return false;
}

std::string simulatePreset(const std::string& preset, const std::string& directory, int frames,
                           double surface_max_range_m, const std::string& extra_format) {
  SimulateOptions options;
  options.surface_max_range_m = surface_max_range_m;
  for (const Preset& candidate : kPresets)
    if (preset == candidate.name)
      options.formats = std::string(candidate.formats) + (extra_format.empty() ? "" : "," + extra_format);
  options.preset = preset;
  options.output_directory = directory;
  options.frames = frames;
  runSimulate(options);
  const std::filesystem::path clouds = std::filesystem::path(directory) / "clouds";
  return options.formats.find("pcd") != std::string::npos ? clouds.string() : directory;
}

void addSimulateCommand(Command& rim) {
  auto options = std::make_shared<SimulateOptions>();
  Command& command =
      rim.subcommand("simulate", "Simulate a spinning LiDAR in a scene: sensor data plus exact ground truth");
  command.option("--preset", options->preset, "ready-made sequence").check(oneOf(simulationPresetNames()));
  command.option("--out,-o", options->output_directory, "output directory").required();
  command.option("--frames", options->frames, "number of scans (default: the preset's)").check(inRange(1, 100000));
  command.option("--seed", options->seed, "scene, motion and noise seed");
  command.option("--sensor", options->sensor,
                 "Ouster metadata JSON, OS-0-128, OS-1-128, hdl64, or a named model (" + sensorCatalogNames() + ")");
  command.option("--scene", options->scene, "indoor, outdoor, traffic (with moving actors), or a PLY/OBJ mesh");
  command.option("--motion", options->motion,
                 "car, cart, handheld, traffic (the traffic scene's stop-and-go), or a KITTI/TUM pose file");
  command.flag("--no-actors", options->no_actors, "the traffic scene without its moving actors");
  command.option("--formats", options->formats,
                 "comma-separated: pcap, bag, points-bag (Ouster), kitti (HDL-64E), pcd (clouds/ of binary PCD "
                 "scans with per-point time, any sensor)");
  command.option("--profile", options->profile, "Ouster UDP profile of the packets")
      .check(oneOf({"LEGACY", "RNG19_RFL8_SIG16_NIR16", "RNG19_RFL8_SIG16_NIR16_DUAL", "RNG15_RFL8_NIR8"}));
  command.option("--cloud-layout", options->cloud_layout,
                 "PointCloud2 layout in points.bag: the simulator's (organized, unorganized, plain) or a driver's "
                 "(ouster-ros, velodyne, hesai)")
      .check(oneOf({"organized", "unorganized", "plain", "ouster-ros", "velodyne", "hesai"}));
  command.option("--noise", options->noise_sigma_m, "range noise sigma, metres").check(inRange(0.0, 1.0));
  command.option("--dropout", options->dropout, "probability of a lost return").check(inRange(0.0, 1.0));
  command.option("--min-range", options->min_range_m, "metres");
  command.option("--max-range", options->max_range_m, "metres");
  command.option("--divergence", options->divergence_rad, "beam divergence, radians");
  command.flag("--no-motion-distortion", options->no_motion_distortion,
               "cast each whole scan from the pose at its first column");
  command.option("--surface-spacing", options->surface_spacing_m,
                 "spacing of the ground-truth surface samples, metres (default 0.02 indoors, 0.075 otherwise)")
      .check(inRange(0.0, 1.0));
  command.option("--seen-distance", options->seen_distance_m,
                 "a surface sample is seen when a noise-free hit lies about this close, metres (default: the "
                 "sample spacing, at least 0.02)")
      .check(inRange(0.0, 1.0));
  command.option("--surface-max-range", options->surface_max_range_m,
                 "the ground-truth surface holds only what was seen this close, metres (0: all); e.g. a "
                 "map's range clip")
      .check(nonNegative());
  command.callback([options] { runSimulate(*options); });
}

}  // namespace range_image_mapping::tool
