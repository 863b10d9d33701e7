// The mapping stack on simulated 128 x 1024 sequences at 10 Hz, 2 threads:
// TSDF integration rate with block edge 8 and 16 (which chooses the default),
// incremental mesh update after every scan (10 Hz driving), without a budget
// and with MeshOptions::update_budget_s (then what waits for later updates),
// a full extraction, memory, and F-scores at 3, 1 and 0.5 voxels against the
// exact seen surface, and at 3 voxels with precision judged against every
// surface of the scene near the route (a mesh filled in between beam rings
// lies on the scene, though no hit fell there); OctoMap (insertPointCloud, the paper's occupancy
// baseline, single-threaded as Debian builds it) on the same scans, its
// F-scores, and the speed ratio ours / OctoMap (paper: 15-50x). Prints one
// table; never asserts a time.
//
// Usage: mapping_benchmark [frames=50] [octomap=1] [mesh_budget_ms=15]
//   frames          consecutive scans per sequence (outdoor_car 10 cm / 30 m
//                   clip, indoor_cart 4 cm / 10 m clip)
//   octomap         0 skips OctoMap (about 2 s per scan on one core)
//   mesh_budget_ms  the budget of the budgeted mesh row (edge 8)
#include "machine_info.h"
#include "octomap_baseline.h"
#include "simulated_mapping_sequence.h"
#include "timing.h"

#include "range_image_mapping/evaluation/surface_metrics.h"
#include "range_image_mapping/mapping/marching_cubes.h"
#include "range_image_mapping/mapping/tsdf_integrator.h"
#include "range_image_mapping/mapping/voxel_block_grid.h"

#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <string>
#include <thread>
#include <vector>

namespace range_image_mapping {
namespace {

using namespace benchmark_support;
constexpr int kThreads = 2;

double median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

// F-scores at these multiples of the voxel (the paper's 3, and finer).
constexpr double kThresholdVoxels[] = {3.0, 1.0, 0.5};

// One row of the table.
struct Row {
  std::string method;
  std::vector<double> insert_wall_s, insert_cpu_s;  // per scan
  std::vector<double> mesh_update_s, mesh_update_cpu_s;  // per scan (ours)
  std::vector<double> mesh_pending;                      // blocks left waiting by the budget, per scan
  std::vector<double> mesh_blocks;                       // blocks re-meshed, per scan
  double full_mesh_s = 0.0;
  std::size_t cells = 0, memory_bytes = 0, triangles = 0;
  evaluation::SurfaceMetrics metrics[3];  // at kThresholdVoxels
  double scene_precision = 0.0, scene_f_score = 0.0;  // at 3 voxels, precision against the whole scene
};

void printHeader() {
  std::printf("%-12s %-14s %7s %7s %6s %7s %8s %8s %8s %8s %8s %8s %8s %8s %7s %6s %6s %6s %6s %6s %6s %6s\n",
              "sequence",
              "method", "ins ms", "median", "Hz", "cpu ms", "mesh ms", "mesh p95", "mesh max", "mesh cpu", "remeshed", "waiting",
              "full ms", "kilo-tri", "cells", "MB", "R@3", "F@3", "F@1", "F@0.5", "Pscene", "Fscene");
}

void printRow(const std::string& sequence, const Row& row) {
  const double wall = mean(row.insert_wall_s);
  // OctoMap has no mesh: its mesh columns are dashes.
  char meshing[140] = "       -        -        -        -        -        -        -        -";
  if (!row.mesh_update_s.empty())
    std::snprintf(meshing, sizeof meshing, "%8.2f %8.2f %8.2f %8.2f %8.0f %8.0f %8.1f %8zu", median(row.mesh_update_s) * 1e3,
                  percentile(row.mesh_update_s, 0.95) * 1e3,
                  *std::max_element(row.mesh_update_s.begin(), row.mesh_update_s.end()) * 1e3,
                  median(row.mesh_update_cpu_s) * 1e3, median(row.mesh_blocks), median(row.mesh_pending), row.full_mesh_s * 1e3,
                  row.triangles / 1000);
  std::printf("%-12s %-14s %7.1f %7.1f %6.2f %7.1f %s %7zu %6.1f %6.4f %6.4f %6.4f %6.4f %6.4f %6.4f\n", sequence.c_str(),
              row.method.c_str(), wall * 1e3, median(row.insert_wall_s) * 1e3, 1.0 / wall,
              mean(row.insert_cpu_s) * 1e3, meshing, row.cells, row.memory_bytes / 1e6, row.metrics[0].recall,
              row.metrics[0].f_score, row.metrics[1].f_score, row.metrics[2].f_score, row.scene_precision,
              row.scene_f_score);
}

// The scene's surfaces near the route, seen or not (precision's truth for Pscene).
struct SequenceAndScene {
  test::SimulatedMappingSequence sequence;
  std::vector<Eigen::Vector3f> scene;
};

void scoreSurface(const std::vector<Eigen::Vector3f>& surface, const test::MappingPreset& preset,
                  const SequenceAndScene& truth, Row& row) {
  for (int t = 0; t < 3; ++t)
    row.metrics[t] =
        evaluation::compareSurfaces(surface, truth.sequence.surface, kThresholdVoxels[t] * preset.voxel_m);
  row.scene_precision = evaluation::shareBelow(evaluation::nearestDistances(surface, truth.scene),
                                               kThresholdVoxels[0] * preset.voxel_m);
  row.scene_f_score = evaluation::fScore(row.scene_precision, row.metrics[0].recall);
}

// Ours: integrate every scan, then update the mesh after it, as a 10 Hz
// driver would (within mesh_budget_s if positive); a full extraction at the end.
Row runOurs(const test::MappingPreset& preset, const SequenceAndScene& truth, int block_edge,
            double mesh_budget_s = 0.0) {
  const test::SimulatedMappingSequence& sequence = truth.sequence;
  mapping::VoxelBlockGridOptions grid_options;
  grid_options.voxel_size_m = preset.voxel_m;
  grid_options.block_edge = block_edge;
  mapping::VoxelBlockGrid grid(grid_options);
  mapping::TsdfIntegratorOptions integrator_options;
  integrator_options.min_range_m = preset.min_range_m;
  integrator_options.max_range_m = preset.max_range_m;
  mapping::TsdfIntegrator integrator(integrator_options);
  mapping::MeshOptions mesh_options;
  mesh_options.update_budget_s = mesh_budget_s;
  mapping::MeshExtractor extractor(mesh_options);
  Row row;
  row.method = "edge " + std::to_string(block_edge);
  if (mesh_budget_s > 0.0) row.method += ", " + std::to_string(int(std::lround(mesh_budget_s * 1e3))) + " ms";
  for (std::size_t k = 0; k < sequence.scans.size(); ++k) {
    const Timer integration;
    integrator.integrate(grid, sequence.scans[k], sequence.poses[k]);
    row.insert_wall_s.push_back(integration.wall());
    row.insert_cpu_s.push_back(integration.cpu());
    const Timer meshing;
    const mapping::MeshUpdate update = extractor.update(grid);
    row.mesh_update_s.push_back(meshing.wall());
    row.mesh_update_cpu_s.push_back(meshing.cpu());
    row.mesh_pending.push_back(double(update.pending));
    row.mesh_blocks.push_back(double(update.changed.size()));
  }
  const Timer full;
  const TriangleMesh mesh = mapping::extractMesh(grid);
  row.full_mesh_s = full.wall();
  row.cells = grid.blockCount();
  row.memory_bytes = grid.memoryBytes();
  row.triangles = mesh.triangles.size();
  scoreSurface(test::meshSamples(mesh, preset.sampleSpacingM()), preset, truth, row);
  return row;
}

// OctoMap on the same scans; its surface is the occupied leaf centres.
Row runOctomap(const test::MappingPreset& preset, const SequenceAndScene& truth) {
  const test::SimulatedMappingSequence& sequence = truth.sequence;
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
  scoreSurface(octomap.occupiedCentres(), preset, truth, row);
  return row;
}

int run(int argc, char** argv) {
  const int frames = argc > 1 ? std::atoi(argv[1]) : 50;
  const bool with_octomap = argc > 2 ? std::atoi(argv[2]) != 0 : true;
  const double mesh_budget_s = (argc > 3 ? std::atof(argv[3]) : 15.0) * 1e-3;
  if (frames < 1 || !(mesh_budget_s > 0.0)) {
    std::fprintf(stderr, "frames must be >= 1 and mesh_budget_ms > 0\n");
    return 2;
  }
  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, kThreads);
  std::printf("mapping_benchmark %s  %s, nproc %u, %d threads used, load average %s\n", now().c_str(),
              cpuModel().c_str(), std::thread::hardware_concurrency(), kThreads, loadAverage().c_str());
  std::printf("ins ms: integration (ours, %d threads) or insertPointCloud (OctoMap, 1 thread) per scan, wall;\n"
              "cpu ms: process CPU time of it (mean); mesh: incremental mesh update after each scan, wall median,\n"
              "95th percentile and max, CPU median; remeshed: blocks re-meshed per update (median); waiting: changed blocks the budget left for later updates\n"
              "(median); full ms: one extraction of the whole grid at the end; cells: blocks (ours) or leaves\n"
              "(OctoMap); R@3: recall at 3 x voxel, F@n: F-score at n x voxel against the seen surface;\n"
              "Pscene, Fscene: precision at 3 x voxel against every surface of the scene near the route, F with it.\n",
              kThreads);
  for (const test::MappingPreset& preset : {test::outdoorCarPreset(), test::indoorCartPreset()}) {
    const Timer simulation;
    SequenceAndScene truth;
    truth.sequence = test::simulateMappingSequence(preset, frames, 1);
    truth.scene = test::sceneSurfaceNearRoute(preset, truth.sequence);
    const test::SimulatedMappingSequence& sequence = truth.sequence;
    std::printf("%s: %d scans of %d x %d at 10 Hz, voxel %.2f m, clip %.0f m, %zu ground-truth samples at %.3f m "
                "(simulated in %.1f s)\n",
                preset.name.c_str(), frames, sequence.model->rows(), sequence.model->columns(), preset.voxel_m,
                preset.max_range_m, sequence.surface.size(), preset.sampleSpacingM(), simulation.wall());
    printHeader();
    const Row edge8 = runOurs(preset, truth, 8);
    printRow(preset.name, edge8);
    printRow(preset.name, runOurs(preset, truth, 16));
    printRow(preset.name, runOurs(preset, truth, 8, mesh_budget_s));
    if (with_octomap) {
      const Row octomap = runOctomap(preset, truth);
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
  using range_image_mapping::benchmark_support::runReportingErrors;
  return runReportingErrors("mapping_benchmark", range_image_mapping::run, argc, argv);
}
