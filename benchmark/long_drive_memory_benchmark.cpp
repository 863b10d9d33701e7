// Issue 5, bounded memory for long runs: one hour of outdoor_car driving
// (36000 scans at 10 Hz), simulated on the fly in memory (never written to
// disk: an hour of OS1-128 scans is many GB) and integrated into a TsdfMap at
// the ground-truth pose, with blocks beyond memory_radius dropped and the
// mesh updated every few scans as the Mapper does. Every sample_every scans
// it records the process RSS (/proc/self/status), the heap in use (glibc
// mallinfo2) and what the map accounts for itself (blocks, bytes, mesh). The
// verdict compares the growth of the peak over the second half of the drive
// with the growth over the first half of the same run (which holds the
// warm-up, the map filling the radius): flat memory means the second half
// adds next to nothing. Prints ratios, never asserts a time or a size.
//
// Mapping, not simulation, sets the cost (about 100-150 ms per scan on 2
// shared cores whatever the sensor's resolution: the voxels of the blocks
// near the surface), so an hour takes about an hour of wall time or more;
// --beams 64 --columns 512 keeps the simulation's share small.
//
// Usage: long_drive_memory_benchmark [--frames 36000] [--beams 128|64]
//          [--columns 512|1024|2048] [--memory-radius 40] [--keep-dropped-mesh]
//          [--mesh-every 10] [--sample-every 1000] [--scene-extent 1000]
//          [--threads 2] [--block-edge 8|16] [--csv FILE]
#include "command_line.h"
#include "machine_info.h"
#include "simulated_mapping_sequence.h"

#include "range_image_mapping/pipeline/scan_to_map_pipeline.h"
#include "range_image_mapping/scan_motion.h"

#include <malloc.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace range_image_mapping {
namespace {

using namespace benchmark_support;
using Clock = std::chrono::steady_clock;

constexpr double kFrequencyHz = 10.0;
constexpr double kMebibyte = 1024.0 * 1024.0;
// Trajectories last at most an hour (MotionOptions::duration_s), so the drive
// starts at t = 0 (not rim simulate's 1 s) for 36000 whole revolutions to fit.
constexpr double kStartS = 0.0;
constexpr double kLongestTrajectoryS = 3600.0;
constexpr uint32_t kSeed = 1;  // as rim simulate and simulateMappingSequence
// Second-half growth below this share of the first half's counts as flat.
constexpr double kFlatShare = 0.10;

struct Options {
  int frames = 36000;
  int beams = 128;
  int columns = 1024;
  double memory_radius_m = 40.0;
  bool keep_dropped_mesh = false;
  int mesh_every = 10;  // the Mapper's default mesh_rate (1 Hz) at 10 Hz scans
  int sample_every = 1000;
  double scene_extent_m = 1000.0;  // the largest street grid the generator makes: the longest lap
  int threads = 2;
  int block_edge = mapping::VoxelBlockGridOptions{}.block_edge;
  std::string csv;
};

void printUsage() {
  std::printf(
      "usage: long_drive_memory_benchmark [options]\n"
      "  --frames N            scans at 10 Hz (default 36000 = one hour; at most 36000)\n"
      "  --beams 128|64        every beam of the OS1-128-like sensor, or every second one\n"
      "  --columns 512|1024|2048  columns per revolution (default 1024)\n"
      "  --memory-radius M     drop blocks farther than M metres (default 40; 0 keeps all)\n"
      "  --keep-dropped-mesh   keep the mesh of dropped blocks (default: drop it too)\n"
      "  --mesh-every N        incremental mesh update every N scans (default 10)\n"
      "  --sample-every N      memory sample every N scans (default 1000)\n"
      "  --scene-extent M      side of the street grid, 120-1000 m (default 1000)\n"
      "  --threads N           TBB threads (default 2)\n"
      "  --block-edge 8|16     voxels per block edge (default: the grid's default)\n"
      "  --csv FILE            also write the samples as CSV\n");
}

Options parseOptions(int argc, char** argv) {
  Options options;
  for (benchmark_support::ArgumentCursor arguments(argc, argv); arguments.next();) {
    const std::string name = arguments.name();
    if (name == "--frames") options.frames = arguments.integer();
    else if (name == "--beams") options.beams = arguments.integer();
    else if (name == "--columns") options.columns = arguments.integer();
    else if (name == "--memory-radius") options.memory_radius_m = arguments.number();
    else if (name == "--keep-dropped-mesh") options.keep_dropped_mesh = true;
    else if (name == "--mesh-every") options.mesh_every = arguments.integer();
    else if (name == "--sample-every") options.sample_every = arguments.integer();
    else if (name == "--scene-extent") options.scene_extent_m = arguments.number();
    else if (name == "--threads") options.threads = arguments.integer();
    else if (name == "--block-edge") {
      options.block_edge = arguments.integer();
      mapping::VoxelBlockGridOptions grid;  // refused here, before the scene is built
      grid.block_edge = options.block_edge;
      grid.validate();
    }
    else if (name == "--csv") options.csv = arguments.value();
    else if (name == "--help" || name == "-h") {
      printUsage();
      std::exit(0);
    } else {
      throw std::invalid_argument("unknown option " + name + " (--help lists them)");
    }
  }
  const int longest = int(std::floor((kLongestTrajectoryS - kStartS) * kFrequencyHz));
  if (options.frames < 1 || options.frames > longest)
    throw std::invalid_argument("--frames must be within [1, " + std::to_string(longest) +
                                "]: the simulator's trajectories last at most an hour");
  if (options.beams != 128 && options.beams != 64) throw std::invalid_argument("--beams must be 128 or 64");
  if (options.columns != 512 && options.columns != 1024 && options.columns != 2048)
    throw std::invalid_argument("--columns must be 512, 1024 or 2048");
  if (options.mesh_every < 1 || options.sample_every < 1 || options.threads < 1)
    throw std::invalid_argument("--mesh-every, --sample-every and --threads must be >= 1");
  return options;
}

// The OS1-128-like sensor of the outdoor_car preset, or a cheaper one with
// every second beam and/or another column count, as Ouster's 64-beam and
// 512x10 / 2048x10 modes are: the same field of view, the destagger shifts
// scaled with the columns. The mapped area, hence the map's memory, is the
// same; only the cost per scan changes.
LidarModelConstPtr sensorModel(const test::MappingPreset& preset, int beams, int columns) {
  const LidarModelConstPtr full = test::ousterLikeModel(preset.product);
  if (beams == full->rows() && columns == full->columns()) return full;
  const LidarIntrinsics& source = full->intrinsics();
  LidarIntrinsics intrinsics = source;
  const int beam_step = source.rows / beams;
  intrinsics.rows = beams;
  intrinsics.columns = columns;
  intrinsics.altitude_rad.clear();
  intrinsics.azimuth_offset_rad.clear();
  intrinsics.pixel_shift_by_row.clear();
  for (int row = 0; row < source.rows; row += beam_step) {
    intrinsics.altitude_rad.push_back(source.altitude_rad[row]);
    intrinsics.azimuth_offset_rad.push_back(source.azimuth_offset_rad[row]);
    const int shift = source.pixel_shift_by_row.empty() ? 0 : source.pixel_shift_by_row[row];
    intrinsics.pixel_shift_by_row.push_back(int(std::lround(double(shift) * columns / source.columns)));
  }
  intrinsics.column_window = {0, -1};
  intrinsics.sensor_model = source.sensor_model + " (" + std::to_string(beams) + "x" + std::to_string(columns) + ")";
  intrinsics.validate();
  return std::make_shared<const LidarModel>(intrinsics);
}

double routeLengthM(const std::vector<Eigen::Vector3d>& route) {
  double length = 0.0;
  for (std::size_t i = 1; i < route.size(); ++i) length += (route[i] - route[i - 1]).norm();
  return length;
}

// Kilobytes are what /proc/self/status reports.
double statusMebibytes(const char* field) {
  std::ifstream file("/proc/self/status");
  const std::string prefix = std::string(field) + ":";
  for (std::string line; std::getline(file, line);)
    if (line.rfind(prefix, 0) == 0) return std::atof(line.c_str() + prefix.size()) * 1024.0 / kMebibyte;
  return 0.0;
}

// Heap bytes handed out and not freed, all arenas plus mmapped chunks: if RSS
// grows while this stays flat, the allocator keeps freed pages (fragmentation),
// not the program.
// mallinfo2 is glibc >= 2.33; older glibc (Debian bullseye: 2.31) has only
// mallinfo, whose int fields wrap past 2 GiB.
double heapInUseMebibytes() {
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 33))
  const struct mallinfo2 info = mallinfo2();
  return double(info.uordblks + info.hblkhd) / kMebibyte;
#else
  const struct mallinfo info = mallinfo();
  return (double(static_cast<unsigned int>(info.uordblks)) + double(static_cast<unsigned int>(info.hblkhd))) /
         kMebibyte;
#endif
}

// What the mesh chunks hold (their arrays' capacity), the kept dropped
// chunks included: TsdfMap::statistics() counts the voxels only.
std::size_t chunkBytes(const mapping::MeshChunk& chunk) {
  return sizeof(mapping::MeshChunk) + chunk.vertices.capacity() * sizeof(Eigen::Vector3f) +
         chunk.normals.capacity() * sizeof(Eigen::Vector3f) + chunk.intensities.capacity() * sizeof(float) +
         chunk.triangles.capacity() * sizeof(Eigen::Vector3i) +
         chunk.vertex_edges.capacity() * sizeof(mapping::LatticeEdge);
}

struct Sample {
  int frames = 0;
  double simulated_s = 0.0, wall_s = 0.0, driven_km = 0.0;
  double rss_mib = 0.0, peak_rss_mib = 0.0, heap_mib = 0.0;
  std::size_t blocks = 0, blocks_dropped = 0, triangles = 0, dropped_triangles = 0;
  double map_mib = 0.0, mesh_mib = 0.0;
  double simulation_ms = 0.0, mapping_ms = 0.0;  // per scan since the previous sample, wall
};

Sample takeSample(int frames, double wall_s, double driven_km, const mapping::TsdfMap& map,
                  std::size_t blocks_dropped) {
  Sample sample;
  sample.frames = frames;
  sample.simulated_s = frames / kFrequencyHz;
  sample.wall_s = wall_s;
  sample.driven_km = driven_km;
  sample.rss_mib = statusMebibytes("VmRSS");
  sample.peak_rss_mib = statusMebibytes("VmHWM");
  sample.heap_mib = heapInUseMebibytes();
  const mapping::MapStatistics statistics = map.statistics();
  sample.blocks = statistics.blocks;
  sample.blocks_dropped = blocks_dropped;
  sample.map_mib = double(statistics.memory_bytes) / kMebibyte;
  sample.triangles = statistics.triangles;
  std::size_t mesh_bytes = 0;
  for (const mapping::MeshChunk* chunk : map.mesh().chunks()) mesh_bytes += chunkBytes(*chunk);
  for (const mapping::MeshChunk& chunk : map.droppedChunks()) {
    mesh_bytes += chunkBytes(chunk);
    sample.dropped_triangles += chunk.triangles.size();
  }
  sample.mesh_mib = double(mesh_bytes) / kMebibyte;
  return sample;
}

void printTableHeader() {
  std::printf("%7s %7s %8s %7s %8s %8s %8s %8s %8s %9s %9s %8s %8s %8s\n", "scans", "sim s", "wall s", "km",
              "RSS MiB", "peak MiB", "heap MiB", "map MiB", "mesh MiB", "blocks", "dropped", "k-tri", "sim ms",
              "map ms");
}

void printSample(const Sample& sample) {
  std::printf("%7d %7.0f %8.0f %7.2f %8.1f %8.1f %8.1f %8.1f %8.1f %9zu %9zu %8.1f %8.1f %8.1f\n", sample.frames,
              sample.simulated_s, sample.wall_s, sample.driven_km, sample.rss_mib, sample.peak_rss_mib,
              sample.heap_mib, sample.map_mib, sample.mesh_mib, sample.blocks, sample.blocks_dropped,
              double(sample.triangles + sample.dropped_triangles) / 1e3, sample.simulation_ms, sample.mapping_ms);
  std::fflush(stdout);
}

void writeCsv(const std::string& path, const std::vector<Sample>& samples) {
  std::ofstream file(path);
  file << "scans,simulated_s,wall_s,driven_km,rss_mib,peak_rss_mib,heap_in_use_mib,map_mib,mesh_mib,blocks,"
          "blocks_dropped,triangles,dropped_triangles,simulation_ms_per_scan,mapping_ms_per_scan\n";
  for (const Sample& sample : samples)
    file << sample.frames << ',' << sample.simulated_s << ',' << sample.wall_s << ',' << sample.driven_km << ','
         << sample.rss_mib << ',' << sample.peak_rss_mib << ',' << sample.heap_mib << ',' << sample.map_mib << ','
         << sample.mesh_mib << ',' << sample.blocks << ',' << sample.blocks_dropped << ',' << sample.triangles
         << ',' << sample.dropped_triangles << ',' << sample.simulation_ms << ',' << sample.mapping_ms << '\n';
  if (!file) throw std::runtime_error("cannot write " + path);
}

// Growth of one quantity over each half of the drive, per simulated hour.
// The map and mesh breathe with the scenery (a square, a street of tall
// facades), so end points would judge a dip or a bump: the halves compare
// their peaks, which is what bounds memory. First half: its peak above the
// start (the warm-up); second half: its peak above the first half's.
void printGrowth(const char* name, const std::vector<Sample>& samples, std::size_t middle,
                 double (*value)(const Sample&)) {
  double first_peak = value(samples.front()), second_peak = value(samples[middle + 1]);
  for (std::size_t i = 0; i <= middle; ++i) first_peak = std::max(first_peak, value(samples[i]));
  for (std::size_t i = middle + 1; i < samples.size(); ++i) second_peak = std::max(second_peak, value(samples[i]));
  const double first_half = first_peak - value(samples.front());
  const double second_half = second_peak - first_peak;
  const double first_hours = (samples[middle].simulated_s - samples.front().simulated_s) / 3600.0;
  const double second_hours = (samples.back().simulated_s - samples[middle].simulated_s) / 3600.0;
  // Flat: the second half adds less than kFlatShare of what the first did
  // (or less than 1 MiB, below what RSS sampling resolves).
  const bool flat = second_half <= std::max(kFlatShare * first_half, 1.0);
  std::printf("%-5s start %7.1f, end %7.1f, peak first half %7.1f, second half %7.1f MiB; growth first half "
              "%+7.1f MiB (%+8.1f MiB/h), second half %+7.1f MiB (%+8.1f MiB/h), second / first %6.3f: %s\n",
              name, value(samples.front()), value(samples.back()), first_peak, second_peak, first_half,
              first_hours > 0.0 ? first_half / first_hours : 0.0, second_half,
              second_hours > 0.0 ? second_half / second_hours : 0.0,
              first_half != 0.0 ? second_half / first_half : 0.0, flat ? "flat" : "GROWING");
}

int run(int argc, char** argv) {
  const Options options = parseOptions(argc, argv);
  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::size_t(options.threads));
  const test::MappingPreset preset = test::outdoorCarPreset();
  std::printf("long_drive_memory_benchmark %s  %s, nproc %u, %d threads used, load average %s\n", now().c_str(),
              cpuModel().c_str(), std::thread::hardware_concurrency(), options.threads, loadAverage().c_str());

  // The outdoor_car preset as rim simulate builds it (scene, car motion,
  // sensor height, 1 cm range noise), on a larger street grid so that a lap
  // is long; the trajectory loops around the closed route.
  const Clock::time_point setup_started = Clock::now();
  simulation::SceneOptions scene_options;
  scene_options.kind = preset.scene;
  scene_options.seed = kSeed;
  scene_options.extent_m = options.scene_extent_m;
  const simulation::Scene scene = simulation::generateScene(scene_options);
  simulation::MotionOptions motion;
  motion.profile = preset.motion;
  motion.duration_s = std::min(kLongestTrajectoryS, kStartS + (options.frames + 1) / kFrequencyHz);
  motion.seed = kSeed;
  motion.sensor_height_m = preset.sensor_height_m;
  const auto trajectory = simulation::makeTrajectory(scene, motion);
  simulation::SensorEffects effects;
  effects.range_noise_sigma_m = preset.noise_sigma_m;
  const simulation::RayCaster caster(scene.mesh);
  const LidarModelConstPtr model = sensorModel(preset, options.beams, options.columns);
  const simulation::LidarSimulator simulator(model, caster, effects, kSeed, kFrequencyHz);
  const double lap_m = routeLengthM(scene.route);

  mapping::TsdfMapOptions map_options;
  map_options.grid.voxel_size_m = preset.voxel_m;
  map_options.grid.block_edge = options.block_edge;
  map_options.integrator.min_range_m = preset.min_range_m;
  map_options.integrator.max_range_m = preset.max_range_m;
  map_options.memory_radius_m = options.memory_radius_m;
  map_options.keep_dropped_mesh = options.keep_dropped_mesh;
  // The pipeline at the exact poses, meshing every mesh_every scans of scan time.
  pipeline::PipelineOptions pipeline_options;
  pipeline_options.map = map_options;
  pipeline_options.mesh_period_s = options.mesh_every / kFrequencyHz;
  pipeline::ScanToMapPipeline pipeline(pipeline_options);
  const mapping::TsdfMap& map = *pipeline.map();
  const double setup_s = std::chrono::duration<double>(Clock::now() - setup_started).count();

  std::printf("outdoor_car, %d scans of %s (%d x %d) at 10 Hz = %.1f simulated minutes, on the fly in memory;\n"
              "scene %.0f m street grid (%zu triangles), route lap %.2f km, looped; set-up %.1f s.\n"
              "map: voxel %.2f m, block edge %d, clip %.0f m, memory_radius %.0f m (0 = keep all), keep_dropped_mesh %s, "
              "mesh update every %d scans.\n",
              options.frames, model->intrinsics().sensor_model.c_str(), model->rows(), model->columns(),
              options.frames / kFrequencyHz / 60.0, options.scene_extent_m, scene.mesh.triangles.size(),
              lap_m / 1e3, setup_s, preset.voxel_m, options.block_edge, preset.max_range_m, options.memory_radius_m,
              options.keep_dropped_mesh ? "true" : "false", options.mesh_every);
  std::printf("The map's memory depends on the area mapped around the sensor (radius, clip, voxel), not on the\n"
              "sensor's resolution: fewer beams or columns make the hour cheaper to simulate, the memory curve\n"
              "is the same in shape. RSS: /proc/self/status VmRSS (peak: VmHWM); heap: glibc mallinfo2 in use;\n"
              "map MiB: the grid's own accounting (voxels, free blocks kept for reuse, hash table); mesh MiB:\n"
              "the mesh chunks' arrays; k-tri: mesh triangles (kept dropped ones included); sim ms / map ms:\n"
              "simulation and mapping (integration, dropping, mesh updates) wall time per scan since the last row.\n");
  printTableHeader();

  std::vector<Sample> samples;
  samples.push_back(takeSample(0, 0.0, 0.0, map, 0));
  printSample(samples.back());

  const Clock::time_point loop_started = Clock::now();
  simulation::SimulatedScan scan;
  std::size_t blocks_dropped = 0, refused = 0;
  double driven_m = 0.0, simulation_s = 0.0, mapping_s = 0.0;
  double simulation_since_sample_s = 0.0, mapping_since_sample_s = 0.0;
  Eigen::Vector3d previous_position = Eigen::Vector3d::Zero();
  for (int frame = 0; frame < options.frames; ++frame) {
    const Clock::time_point simulation_started = Clock::now();
    const double start = kStartS + frame / kFrequencyHz;
    simulator.simulate(*trajectory, start, uint32_t(frame), scan);
    // As simulateMappingSequence: the exact pose at column 0 and the sweep's true twist.
    pipeline::GivenPose pose;
    pose.world_from_lidar = scan.column_poses.front();
    const double sweep_s = simulator.columnTime(start, model->columns() - 1) - start;
    pose.twist = twistBetween(scan.column_poses.front(), scan.column_poses.back(), sweep_s);
    const Clock::time_point mapping_started = Clock::now();
    const double simulated_for = std::chrono::duration<double>(mapping_started - simulation_started).count();
    simulation_s += simulated_for;
    simulation_since_sample_s += simulated_for;

    const pipeline::ScanResult result = pipeline.process(scan.image, pose);
    if (result.map) blocks_dropped += result.map->blocks_dropped;
    if (!(result.map && result.map->integrated) && refused++ < 5)
      std::fprintf(stderr, "scan %d: %s\n", frame, result.warnings.empty() ? "" : result.warnings.front().c_str());
    const double mapped_for = std::chrono::duration<double>(Clock::now() - mapping_started).count();
    mapping_s += mapped_for;
    mapping_since_sample_s += mapped_for;

    const Eigen::Vector3d position = pose.world_from_lidar.translation();
    if (frame > 0) driven_m += (position - previous_position).norm();
    previous_position = position;

    if ((frame + 1) % options.sample_every == 0 || frame + 1 == options.frames) {
      const int scans_since = frame + 1 - samples.back().frames;
      Sample sample = takeSample(frame + 1, std::chrono::duration<double>(Clock::now() - loop_started).count(),
                                 driven_m / 1e3, map, blocks_dropped);
      sample.simulation_ms = 1e3 * simulation_since_sample_s / scans_since;
      sample.mapping_ms = 1e3 * mapping_since_sample_s / scans_since;
      simulation_since_sample_s = mapping_since_sample_s = 0.0;
      samples.push_back(sample);
      printSample(sample);
      if (!options.csv.empty()) writeCsv(options.csv, samples);  // after every row: a killed run keeps its table
    }
  }

  const Sample& last = samples.back();
  std::printf("done: %d scans (%.1f simulated minutes, %.2f km, %.1f laps) in %.0f s wall (simulation %.0f s, "
              "mapping %.0f s), %zu refused, %zu blocks kept, %zu dropped in all\n",
              last.frames, last.simulated_s / 60.0, last.driven_km, last.driven_km * 1e3 / lap_m, last.wall_s,
              simulation_s, mapping_s, refused, last.blocks, last.blocks_dropped);
  // The sample nearest half-way: the first half is the baseline of the second.
  std::size_t middle = 0;
  for (std::size_t i = 0; i < samples.size(); ++i)
    if (std::abs(samples[i].frames - last.frames / 2.0) < std::abs(samples[middle].frames - last.frames / 2.0))
      middle = i;
  if (middle == 0 || middle + 1 >= samples.size()) {
    std::printf("verdict: too few samples for two halves (use more --frames or a smaller --sample-every)\n");
  } else {
    std::printf("growth (half-way at scan %d; flat = the second half's peak above the first half's by less than "
                "%.0f %% of the first half's growth, or by less than 1 MiB):\n",
                samples[middle].frames, 100.0 * kFlatShare);
    printGrowth("RSS", samples, middle, [](const Sample& sample) { return sample.rss_mib; });
    printGrowth("heap", samples, middle, [](const Sample& sample) { return sample.heap_mib; });
    printGrowth("map", samples, middle, [](const Sample& sample) { return sample.map_mib; });
    printGrowth("mesh", samples, middle, [](const Sample& sample) { return sample.mesh_mib; });
  }
  std::printf("load average at the end: %s\n", loadAverage().c_str());
  if (!options.csv.empty()) std::printf("samples written to %s\n", options.csv.c_str());
  return 0;
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  using range_image_mapping::benchmark_support::runReportingErrors;
  return runReportingErrors("long_drive_memory_benchmark", range_image_mapping::run, argc, argv);
}
