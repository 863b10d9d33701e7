// Cost of simulating one 128 x 1024 frame on ONE core (TBB limited to one
// thread), against the 100 ms budget, in the procedural outdoor scene (car
// on its route, OS1-128 tables when ../shared/data is present) and the indoor
// one (handheld, OS0-128). Baseline measured in the same run: the frame's rays
// cast one by one (rtcIntersect1) against the batched streams the simulator
// uses (rtcIntersect1M, one column per call).
// Prints Google Benchmark's table, then the per-frame figures and ratios.
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/simulation/lidar_simulator.h"
#include "test_data.h"

#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <cstdio>
#include <iostream>
#include <map>
#include <memory>

namespace range_image_mapping::simulation {
namespace {

constexpr double kFrameStartS = 10.0;

LidarModelConstPtr modelFromData(const std::string& json, double fov_deg) {
  const std::string path = test::dataFile("ouster-pcaps/" + json);
  if (!path.empty()) return std::make_shared<const LidarModel>(loadOusterMetadata(path).intrinsics);
  std::cerr << "simulation_benchmark: " << json << " not found, using a synthetic 128 x 1024 model\n";
  const double half = fov_deg / 2 * M_PI / 180;
  return std::make_shared<const LidarModel>(LidarIntrinsics::synthetic(128, 1024, half, -half));
}

struct World {
  std::string name;
  Scene scene;
  LidarModelConstPtr model;
  std::unique_ptr<RayCaster> caster;
  std::unique_ptr<Trajectory> trajectory;
  std::unique_ptr<LidarSimulator> simulator;
  // The frame's rays (world frame, one column after the other), for the caster alone.
  std::vector<Eigen::Vector3f> origins, directions;
  std::size_t valid_pixels = 0;
};

World makeWorld(SceneKind kind) {
  World world;
  const bool outdoor = kind == SceneKind::kOutdoor;
  world.name = outdoor ? "outdoor, car, OS1-128" : "indoor, handheld, OS0-128";
  SceneOptions scene_options;
  scene_options.kind = kind;
  world.scene = generateScene(scene_options);
  world.model = outdoor ? modelFromData("OS-1-128_v2.3.0_1024x10.json", 45)
                        : modelFromData("OS-0-128-U1_v2.3.0_1024x10.json", 90);
  world.caster = std::make_unique<RayCaster>(world.scene.mesh);
  MotionOptions motion;
  motion.profile = outdoor ? MotionProfile::kCar : MotionProfile::kHandheld;
  motion.sensor_height_m = outdoor ? 1.9 : 1.5;
  motion.duration_s = 20.0;
  world.trajectory = makeTrajectory(world.scene, motion);
  SensorEffects effects;
  effects.range_noise_sigma_m = 0.01;
  effects.dropout_probability = 0.01;
  world.simulator = std::make_unique<LidarSimulator>(world.model, *world.caster, effects, 1);
  const SimulatedScan scan = world.simulator->simulate(*world.trajectory, kFrameStartS, 0);
  world.valid_pixels = scan.image.validCount();
  const LidarModel& model = *world.model;
  const double n = std::hypot(model.intrinsics().beam_origin_radius_m, model.intrinsics().beam_origin_z_m);
  for (int u = 0; u < model.columns(); ++u)
    for (int v = 0; v < model.rows(); ++v) {
      const Eigen::Isometry3d& pose = scan.column_poses[u];
      const Eigen::Vector3f start = model.offset(u, v) + float(n) * model.direction(u, v);
      world.origins.push_back((pose * start.cast<double>()).cast<float>());
      world.directions.push_back((pose.linear() * model.direction(u, v).cast<double>()).cast<float>());
    }
  return world;
}

World& world(SceneKind kind) {
  static World outdoor = makeWorld(SceneKind::kOutdoor);
  static World indoor = makeWorld(SceneKind::kIndoor);
  return kind == SceneKind::kOutdoor ? outdoor : indoor;
}

void simulateFrame(benchmark::State& state, SceneKind kind, bool one_core) {
  const World& w = world(kind);
  std::unique_ptr<tbb::global_control> limit;
  if (one_core) limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, 1);
  SimulatedScan scan;
  uint32_t frame = 0;
  for (auto _ : state) {
    w.simulator->simulate(*w.trajectory, kFrameStartS, frame++, scan);
    benchmark::DoNotOptimize(scan.raw.range.data());
  }
}

void castFrameBatched(benchmark::State& state, SceneKind kind) {
  const World& w = world(kind);
  const std::size_t rows = w.model->rows();
  std::vector<float> distances(w.origins.size());
  for (auto _ : state) {
    for (std::size_t first = 0; first < w.origins.size(); first += rows)
      w.caster->cast(&w.origins[first], &w.directions[first], rows, 0.0f, 120.0f, &distances[first]);
    benchmark::DoNotOptimize(distances.data());
  }
}

void castFrameOneByOne(benchmark::State& state, SceneKind kind) {
  const World& w = world(kind);
  std::vector<float> distances(w.origins.size());
  for (auto _ : state) {
    for (std::size_t i = 0; i < w.origins.size(); ++i)
      distances[i] = w.caster->castOne(w.origins[i], w.directions[i], 0.0f, 120.0f);
    benchmark::DoNotOptimize(distances.data());
  }
}

// Keeps each benchmark's real time per iteration so the figures can be printed.
class RatioReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    ConsoleReporter::ReportRuns(runs);
    for (const Run& run : runs)
      if (run.run_type == Run::RT_Iteration) {
        const std::string name = run.benchmark_name().substr(0, run.benchmark_name().find("/real_time"));
        real_ms[name] = run.GetAdjustedRealTime();
        cpu_ms[name] = run.GetAdjustedCPUTime();
      }
  }
  std::map<std::string, double> real_ms, cpu_ms;
};

}  // namespace
}  // namespace range_image_mapping::simulation

int main(int argc, char** argv) {
  using namespace range_image_mapping::simulation;
  benchmark::Initialize(&argc, argv);
  for (SceneKind kind : {SceneKind::kOutdoor, SceneKind::kIndoor}) {
    const World& w = world(kind);
    const std::string tag = kind == SceneKind::kOutdoor ? "outdoor" : "indoor";
    std::cout << tag << ": " << w.name << ", " << w.scene.mesh.triangles.size() << " triangles, "
              << w.model->rows() << " x " << w.model->columns() << " frame, " << w.valid_pixels
              << " returns\n";
    benchmark::RegisterBenchmark(("simulateFrameOneCore/" + tag).c_str(), simulateFrame, kind, true)
        ->Unit(benchmark::kMillisecond)->UseRealTime();
    benchmark::RegisterBenchmark(("simulateFrameAllCores/" + tag).c_str(), simulateFrame, kind, false)
        ->Unit(benchmark::kMillisecond)->UseRealTime();
    benchmark::RegisterBenchmark(("castFrameBatched/" + tag).c_str(), castFrameBatched, kind)
        ->Unit(benchmark::kMillisecond)->UseRealTime();
    benchmark::RegisterBenchmark(("castFrameOneByOne/" + tag).c_str(), castFrameOneByOne, kind)
        ->Unit(benchmark::kMillisecond)->UseRealTime();
  }
  RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  // Single-threaded runs: the calling thread's CPU time is the whole cost (and
  // is not inflated when other processes share the cores).
  auto& t = reporter.cpu_ms;
  auto& real = reporter.real_ms;
  std::cout << "\nper frame (CPU time of the one thread; all cores: real time):\n";
  for (const std::string tag : {"outdoor", "indoor"}) {
    const std::string one = "simulateFrameOneCore/" + tag, all = "simulateFrameAllCores/" + tag;
    const std::string batched = "castFrameBatched/" + tag, single = "castFrameOneByOne/" + tag;
    if (t.count(one))
      std::printf("%-8s simulate, one core   %7.1f ms   (budget 100 ms: %s)\n", tag.c_str(), t[one],
                  t[one] < 100.0 ? "met" : "MISSED");
    if (real.count(all)) std::printf("%-8s simulate, all cores  %7.1f ms\n", tag.c_str(), real[all]);
    if (t.count(batched) && t.count(single))
      std::printf("%-8s rays batched %7.1f ms   baseline one by one %7.1f ms   ratio %.2fx\n",
                  tag.c_str(), t[batched], t[single], t[single] / t[batched]);
  }
  return 0;
}
