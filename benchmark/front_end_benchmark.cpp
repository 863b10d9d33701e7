// Per-frame cost of the front end on one core, for a 128 x 1024 Ouster frame
// (the first lb_n3 scan when ../shared/data is present), each against a
// baseline measured in the same run:
//   decode      packets to a range image in metres, vs copying the frame's
//               packet bytes (the memory-bound floor: the ratio is below 1)
//   unproject   vs the closed-form trigonometry per pixel, without tables
//   project     vs the literal method: atan2/asin per iteration and a linear
//               search over all beams for the row
// Prints Google Benchmark's table, then the ratios.
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/ouster_packet.h"
#include "test_data.h"

#include <benchmark/benchmark.h>

#include <cmath>
#include <cstring>
#include <iostream>
#include <map>

namespace range_image_mapping {
namespace {

struct Fixture {
  OusterMetadata metadata;
  LidarModelConstPtr model;
  std::vector<std::vector<uint8_t>> packets;  // one frame
  RangeImage image;
  std::vector<Eigen::Vector3f> points;
};

Fixture& fixture() {
  static Fixture data = [] {
    Fixture f;
    const std::string pcap = test::dataFile("ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
    const std::string json = test::dataFile("ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
    if (pcap.empty() || json.empty()) {
      std::cerr << "front_end_benchmark needs ../shared/data/ouster-pcaps (or $RIM_DATA_DIR)\n";
      std::exit(1);
    }
    f.metadata = loadOusterMetadata(json);
    f.model = std::make_shared<const LidarModel>(f.metadata.intrinsics);
    const PacketFormat format(f.metadata);
    io::PcapReader reader(pcap);
    io::UdpDatagram datagram;
    uint32_t first_frame = 0;
    while (reader.next(datagram)) {
      if (datagram.size != format.packetSize()) continue;
      const uint32_t frame = format.frameId(datagram.payload);
      if (f.packets.empty()) first_frame = frame;
      if (frame != first_frame) break;
      f.packets.emplace_back(datagram.payload, datagram.payload + datagram.size);
    }
    LidarScan scan(format.rows(), format.columns(), format.profile());
    for (const auto& packet : f.packets) format.decode(packet.data(), packet.size(), scan);
    f.image = toRangeImage(scan, f.model);
    f.points = f.image.unprojectAll();
    return f;
  }();
  return data;
}

void decodeFrame(benchmark::State& state) {
  const Fixture& f = fixture();
  const PacketFormat format(f.metadata);
  LidarScan scan(format.rows(), format.columns(), format.profile());
  RangeImage image(f.model);  // reused, as a pipeline does (a fresh one is mostly page faults)
  for (auto _ : state) {
    scan.reset();
    for (const auto& packet : f.packets) format.decode(packet.data(), packet.size(), scan);
    toRangeImage(scan, f.model, ReturnIndex::kFirst, image);
    benchmark::DoNotOptimize(image.range.data());
  }
}

void copyFramePackets(benchmark::State& state) {
  const Fixture& f = fixture();
  std::vector<uint8_t> destination(f.packets.size() * f.packets.front().size());
  for (auto _ : state) {
    std::size_t offset = 0;
    for (const auto& packet : f.packets) {
      std::memcpy(destination.data() + offset, packet.data(), packet.size());
      offset += packet.size();
    }
    benchmark::DoNotOptimize(destination.data());
    benchmark::ClobberMemory();
  }
}

void unprojectFrame(benchmark::State& state) {
  const Fixture& f = fixture();
  std::vector<Eigen::Vector3f> points(f.image.range.size());
  for (auto _ : state) {
    std::size_t count = 0;
    for (int v = 0; v < f.image.rows(); ++v)
      for (int u = 0; u < f.image.columns(); ++u)
        if (f.image.valid(v, u)) points[count++] = f.model->unproject(u, v, f.image.at(v, u));
    benchmark::DoNotOptimize(points.data());
  }
}

void unprojectFrameWithTrigonometry(benchmark::State& state) {
  const Fixture& f = fixture();
  const LidarIntrinsics& in = f.model->intrinsics();
  std::vector<Eigen::Vector3f> points(f.image.range.size());
  for (auto _ : state) {
    std::size_t count = 0;
    for (int v = 0; v < f.image.rows(); ++v)
      for (int u = 0; u < f.image.columns(); ++u) {
        if (!f.image.valid(v, u)) continue;
        const float r = f.image.at(v, u);
        const float encoder = float(2 * M_PI - 2 * M_PI * u / in.columns);
        const float azimuth = encoder + float(in.azimuth_offset_rad[v]);
        const float altitude = float(in.altitude_rad[v]);
        const float n = float(in.beam_origin_radius_m);
        points[count++] = Eigen::Vector3f(
            (r - n) * std::cos(azimuth) * std::cos(altitude) + n * std::cos(encoder),
            (r - n) * std::sin(azimuth) * std::cos(altitude) + n * std::sin(encoder),
            (r - n) * std::sin(altitude));
      }
    benchmark::DoNotOptimize(points.data());
  }
}

void projectFrame(benchmark::State& state) {
  const Fixture& f = fixture();
  for (auto _ : state) {
    int hits = 0;
    for (const Eigen::Vector3f& point : f.points) hits += f.model->project(point).has_value();
    benchmark::DoNotOptimize(hits);
  }
}

void projectFrameBatched(benchmark::State& state) {
  const Fixture& f = fixture();
  std::vector<ProjectedPixel> pixels(f.points.size());
  std::vector<uint8_t> hits(f.points.size());
  for (auto _ : state) {
    f.model->projectMany(f.points.data(), f.points.size(), pixels.data(), hits.data());
    benchmark::DoNotOptimize(pixels.data());
  }
}

// The paper's procedure written plainly: trig calls in every iteration and
// the nearest beam by a scan over all of them.
void projectFrameLiterally(benchmark::State& state) {
  const Fixture& f = fixture();
  const LidarIntrinsics& in = f.model->intrinsics();
  const float r0 = float(in.beam_origin_radius_m);
  for (auto _ : state) {
    int checksum = 0;
    for (const Eigen::Vector3f& p : f.points) {
      float encoder = std::atan2(p.y(), p.x());
      int row = 0;
      for (int iteration = 0; iteration < 3; ++iteration) {
        const Eigen::Vector3f ray = p - Eigen::Vector3f(r0 * std::cos(encoder), r0 * std::sin(encoder), 0);
        const float altitude = std::asin(ray.z() / ray.norm());
        float best = 1e9f;
        for (int v = 0; v < in.rows; ++v) {
          const float distance = std::abs(float(in.altitude_rad[v]) - altitude);
          if (distance < best) best = distance, row = v;
        }
        encoder = std::atan2(ray.y(), ray.x()) - float(in.azimuth_offset_rad[row]);
      }
      checksum += row + int(f.model->columnOfEncoderAngle(encoder) + 0.5f);
    }
    benchmark::DoNotOptimize(checksum);
  }
}

BENCHMARK(decodeFrame)->Unit(benchmark::kMicrosecond);
BENCHMARK(copyFramePackets)->Unit(benchmark::kMicrosecond);
BENCHMARK(unprojectFrame)->Unit(benchmark::kMicrosecond);
BENCHMARK(unprojectFrameWithTrigonometry)->Unit(benchmark::kMicrosecond);
BENCHMARK(projectFrame)->Unit(benchmark::kMicrosecond);
BENCHMARK(projectFrameBatched)->Unit(benchmark::kMicrosecond);
BENCHMARK(projectFrameLiterally)->Unit(benchmark::kMicrosecond);

// Keeps each benchmark's CPU time per iteration so the ratios can be printed.
class RatioReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    ConsoleReporter::ReportRuns(runs);
    for (const Run& run : runs)
      if (run.run_type == Run::RT_Iteration)
        cpu_microseconds[run.benchmark_name()] = run.GetAdjustedCPUTime();
  }
  std::map<std::string, double> cpu_microseconds;
};

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  using range_image_mapping::fixture;
  benchmark::Initialize(&argc, argv);
  const auto& f = fixture();
  std::cout << "frame: " << f.image.rows() << " x " << f.image.columns() << ", " << f.packets.size()
            << " packets, " << f.points.size() << " valid pixels, profile "
            << range_image_mapping::toString(f.metadata.profile) << ", one core\n";
  range_image_mapping::RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  auto& t = reporter.cpu_microseconds;
  const auto line = [&](const char* what, const std::string& ours, const std::string& baseline) {
    if (!t.count(ours) || !t.count(baseline)) return;
    std::printf("%-10s %9.1f us per frame   baseline %-32s %9.1f us   ratio %.2fx\n", what, t[ours],
                baseline.c_str(), t[baseline], t[baseline] / t[ours]);
  };
  std::cout << "\nper frame (CPU time), ratio = baseline / ours:\n";
  line("decode", "decodeFrame", "copyFramePackets");
  line("unproject", "unprojectFrame", "unprojectFrameWithTrigonometry");
  line("project", "projectFrame", "projectFrameLiterally");
  line("project*", "projectFrameBatched", "projectFrameLiterally");
  std::cout << "(project: LidarModel::project per point; project*: LidarModel::projectMany)\n";
  return 0;
}
