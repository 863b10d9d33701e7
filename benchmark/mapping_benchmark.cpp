// The mapping stack on simulated 128 x 1024 sequences at 10 Hz, 2 threads:
// TSDF integration rate with block edge 8 and 16 (which chooses the default),
// incremental mesh extraction after every scan (10 Hz driving) and a full
// extraction, memory, and F-scores against the exact seen surface; OctoMap
// (insertPointCloud, the paper's occupancy baseline, single-threaded as
// Debian builds it) on the same scans, and the speed ratio ours / OctoMap
// (paper: 15-50x). Prints one table; never asserts a time.
//
// Usage: mapping_benchmark [frames=50] [octomap=1]
//   frames   consecutive scans per sequence (outdoor_car 10 cm / 30 m clip,
//            indoor_cart 4 cm / 10 m clip)
//   octomap  0 skips OctoMap (about 2 s per scan on one core)
#include "octomap_baseline.h"
#include "simulated_mapping_sequence.h"

#include "range_image_mapping/evaluation/surface_metrics.h"
#include "range_image_mapping/mapping/marching_cubes.h"
#include "range_image_mapping/mapping/tsdf_integrator.h"
#include "range_image_mapping/mapping/voxel_block_grid.h"

#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <numeric>
#include <string>
#include <thread>
#include <vector>

namespace range_image_mapping {
namespace {

using Clock = std::chrono::steady_clock;
constexpr int kThreads = 2;

double secondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

// CPU seconds of the whole process (all threads): on a shared machine the wall
// time depends on the load, the CPU time much less.
double processCpuSeconds() {
  timespec time{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &time);
  return double(time.tv_sec) + 1e-9 * double(time.tv_nsec);
}

// Wall and CPU time of one call.
struct Timer {
  Clock::time_point wall_start = Clock::now();
  double cpu_start = processCpuSeconds();
  double wall() const { return secondsSince(wall_start); }
  double cpu() const { return processCpuSeconds() - cpu_start; }
};

double mean(const std::vector<double>& values) {
  return values.empty() ? 0.0 : std::accumulate(values.begin(), values.end(), 0.0) / double(values.size());
}
double median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

std::string cpuModel() {
  std::ifstream file("/proc/cpuinfo");
  for (std::string line; std::getline(file, line);)
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  return "unknown CPU";
}

std::string loadAverage() {
  std::ifstream file("/proc/loadavg");
  std::string one, five, fifteen;
  file >> one >> five >> fifteen;
  return one + " " + five + " " + fifteen;
}

std::string now() {
  const std::time_t time = std::time(nullptr);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%d %H:%M", std::localtime(&time));
  return text;
}

// One row of the table.
struct Row {
  std::string method;
  std::vector<double> insert_wall_s, insert_cpu_s;  // per scan
  std::vector<double> mesh_update_s, mesh_update_cpu_s;  // per scan (ours)
  double full_mesh_s = 0.0;
  std::size_t cells = 0, memory_bytes = 0, triangles = 0;
  evaluation::SurfaceMetrics metrics;
};

void printHeader() {
  std::printf("%-12s %-9s %9s %9s %7s %9s %9s %9s %9s %9s %8s %8s %8s %7s %7s %7s\n", "sequence", "method",
              "ins ms", "median", "Hz", "cpu ms", "mesh ms", "mesh max", "mesh cpu", "full ms", "kilo-tri", "cells",
              "MB", "P", "R", "F");
}

void printRow(const std::string& sequence, const Row& row) {
  const double wall = mean(row.insert_wall_s);
  // OctoMap has no mesh: its mesh columns are dashes.
  char meshing[80] = "        -         -         -         -        -";
  if (!row.mesh_update_s.empty())
    std::snprintf(meshing, sizeof meshing, "%9.2f %9.2f %9.2f %9.1f %8zu", median(row.mesh_update_s) * 1e3,
                  *std::max_element(row.mesh_update_s.begin(), row.mesh_update_s.end()) * 1e3,
                  median(row.mesh_update_cpu_s) * 1e3, row.full_mesh_s * 1e3, row.triangles / 1000);
  std::printf("%-12s %-9s %9.1f %9.1f %7.2f %9.1f %s %8zu %8.1f %7.4f %7.4f %7.4f\n", sequence.c_str(),
              row.method.c_str(), wall * 1e3, median(row.insert_wall_s) * 1e3, 1.0 / wall,
              mean(row.insert_cpu_s) * 1e3, meshing, row.cells, row.memory_bytes / 1e6, row.metrics.precision,
              row.metrics.recall, row.metrics.f_score);
}

// Ours: integrate every scan, then update the mesh after it, as a 10 Hz
// driver would; a full extraction at the end.
Row runOurs(const test::MappingPreset& preset, const test::SimulatedMappingSequence& sequence, int block_edge) {
  mapping::VoxelBlockGridOptions grid_options;
  grid_options.voxel_size_m = preset.voxel_m;
  grid_options.block_edge = block_edge;
  mapping::VoxelBlockGrid grid(grid_options);
  mapping::TsdfIntegratorOptions integrator_options;
  integrator_options.min_range_m = preset.min_range_m;
  integrator_options.max_range_m = preset.max_range_m;
  mapping::TsdfIntegrator integrator(integrator_options);
  mapping::MeshExtractor extractor;
  Row row;
  row.method = "edge " + std::to_string(block_edge);
  for (std::size_t k = 0; k < sequence.scans.size(); ++k) {
    const Timer integration;
    integrator.integrate(grid, sequence.scans[k], sequence.poses[k]);
    row.insert_wall_s.push_back(integration.wall());
    row.insert_cpu_s.push_back(integration.cpu());
    const Timer meshing;
    extractor.update(grid);
    row.mesh_update_s.push_back(meshing.wall());
    row.mesh_update_cpu_s.push_back(meshing.cpu());
  }
  const Timer full;
  const mapping::TriangleMeshData mesh = mapping::extractMesh(grid);
  row.full_mesh_s = full.wall();
  row.cells = grid.blockCount();
  row.memory_bytes = grid.memoryBytes();
  row.triangles = mesh.triangles.size();
  row.metrics = evaluation::compareSurfaces(test::meshSamples(mesh, preset.sampleSpacingM()), sequence.surface,
                                            preset.thresholdM());
  return row;
}

// OctoMap on the same scans; its surface is the occupied leaf centres.
Row runOctomap(const test::MappingPreset& preset, const test::SimulatedMappingSequence& sequence) {
  test::OctomapBaselineOptions options;
  options.resolution_m = preset.voxel_m;
  options.min_range_m = preset.min_range_m;
  options.max_range_m = preset.max_range_m;
  test::OctomapBaseline octomap(options);
  Row row;
  row.method = "OctoMap";
  for (std::size_t k = 0; k < sequence.scans.size(); ++k) {
    const test::OctomapInsertionTime time =
        octomap.insert(sequence.scans[k], sequence.poses[k].world_from_lidar, sequence.poses[k].twist);
    row.insert_wall_s.push_back(time.wall_s);
    row.insert_cpu_s.push_back(time.cpu_s);
  }
  row.cells = octomap.leafCount();
  row.memory_bytes = octomap.memoryBytes();
  row.metrics = evaluation::compareSurfaces(octomap.occupiedCentres(), sequence.surface, preset.thresholdM());
  return row;
}

int run(int argc, char** argv) {
  const int frames = argc > 1 ? std::atoi(argv[1]) : 50;
  const bool with_octomap = argc > 2 ? std::atoi(argv[2]) != 0 : true;
  if (frames < 1) {
    std::fprintf(stderr, "frames must be >= 1\n");
    return 2;
  }
  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, kThreads);
  std::printf("mapping_benchmark %s  %s, nproc %u, %d threads used, load average %s\n", now().c_str(),
              cpuModel().c_str(), std::thread::hardware_concurrency(), kThreads, loadAverage().c_str());
  std::printf("ins ms: integration (ours, %d threads) or insertPointCloud (OctoMap, 1 thread) per scan, wall;\n"
              "cpu ms: process CPU time of it (mean); mesh: incremental mesh update after each scan, wall median and\n"
              "max, CPU median; full ms: one extraction of the whole grid at the end;\n"
              "cells: blocks (ours) or leaves (OctoMap); P/R/F at 3 x voxel against the seen surface.\n",
              kThreads);
  for (const test::MappingPreset& preset : {test::outdoorCarPreset(), test::indoorCartPreset()}) {
    const Timer simulation;
    const test::SimulatedMappingSequence sequence = test::simulateMappingSequence(preset, frames, 1);
    std::printf("%s: %d scans of %d x %d at 10 Hz, voxel %.2f m, clip %.0f m, %zu ground-truth samples at %.3f m "
                "(simulated in %.1f s)\n",
                preset.name.c_str(), frames, sequence.model->rows(), sequence.model->columns(), preset.voxel_m,
                preset.max_range_m, sequence.surface.size(), preset.sampleSpacingM(), simulation.wall());
    printHeader();
    const Row edge8 = runOurs(preset, sequence, 8);
    printRow(preset.name, edge8);
    printRow(preset.name, runOurs(preset, sequence, 16));
    if (with_octomap) {
      const Row octomap = runOctomap(preset, sequence);
      printRow(preset.name, octomap);
      std::printf("%s: ours (edge 8) / OctoMap per scan: %.1fx faster in wall time, %.1fx less CPU time\n",
                  preset.name.c_str(), mean(octomap.insert_wall_s) / mean(edge8.insert_wall_s),
                  mean(octomap.insert_cpu_s) / mean(edge8.insert_cpu_s));
    }
  }
  std::printf("load average at the end: %s\n", loadAverage().c_str());
  return 0;
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  try {
    return range_image_mapping::run(argc, argv);
  } catch (const std::exception& error) {
    std::fprintf(stderr, "mapping_benchmark: %s\n", error.what());
    return 1;
  }
}
