// libFuzzer: arbitrary bytes as a stream of lidar packets into a ScanBatcher,
// for fixed sensor layouts built here (no files), and every emitted scan into
// a range image. Must never crash, leak or trip the sanitizers.
//
// Input: byte 0 picks the layout; then records of one operation byte and, for
// packets, the packet bytes:
//   op % 4 == 0: a packet of exactly the layout's size (or what is left)
//   op % 4 == 1: a packet whose size is the next two bytes (little-endian)
//   op % 4 == 2: flush()
//   op % 4 == 3: a packet one byte short of the layout's size
// scripts/run_fuzzers.sh writes seeds in this form from real captures.
#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/scan_batcher.h"

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <vector>

namespace rim = range_image_mapping;

namespace {

struct Layout {
  rim::UdpProfile profile;
  int rows;
  int columns;
  int columns_per_packet;
  std::array<int, 2> column_window;
};

// Keep in the order of scripts/run_fuzzers.sh, which names seeds by index.
const Layout kLayouts[] = {
    {rim::UdpProfile::kLegacy, 16, 1024, 16, {0, 1023}},
    {rim::UdpProfile::kLegacy, 32, 1024, 16, {0, 1023}},                   // OS-1-32-G, OS-2-32-U0
    {rim::UdpProfile::kLegacy, 64, 1024, 16, {0, 1023}},                   // OS-1-64
    {rim::UdpProfile::kRng19Rfl8Sig16Nir16, 128, 1024, 16, {0, 1023}},     // OS-2-128
    {rim::UdpProfile::kRng19Rfl8Sig16Nir16Dual, 32, 1024, 16, {0, 1023}},  // OS-0-32
    {rim::UdpProfile::kRng15Rfl8Nir8, 128, 1024, 16, {0, 1023}},           // lb_n3, OS-0-128
    {rim::UdpProfile::kRng15Rfl8Nir8, 128, 512, 16, {370, 85}},            // crc_test, windowed
    {rim::UdpProfile::kRng19Rfl8Sig16Nir16, 16, 512, 8, {1, 256}},
};
constexpr std::size_t kLayoutCount = sizeof(kLayouts) / sizeof(kLayouts[0]);

struct Sensor {
  rim::OusterMetadata metadata;
  rim::LidarModelConstPtr model;
};

const Sensor& sensor(std::size_t index) {
  static std::vector<std::unique_ptr<Sensor>> sensors(kLayoutCount);
  if (!sensors[index]) {
    const Layout& layout = kLayouts[index];
    auto made = std::make_unique<Sensor>();
    made->metadata.profile = layout.profile;
    made->metadata.pixels_per_column = layout.rows;
    made->metadata.columns_per_frame = layout.columns;
    made->metadata.columns_per_packet = layout.columns_per_packet;
    made->metadata.intrinsics =
        rim::LidarIntrinsics::synthetic(layout.rows, layout.columns, 0.4, -0.4);
    made->metadata.intrinsics.column_window = layout.column_window;
    made->model = std::make_shared<const rim::LidarModel>(made->metadata.intrinsics);
    sensors[index] = std::move(made);
  }
  return *sensors[index];
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const Sensor& chosen = sensor(data[0] % kLayoutCount);
  std::size_t emitted = 0;
  rim::ScanBatcher batcher(chosen.metadata, [&](const rim::LidarScan& scan) {
    // Converting is the same code for every size, and a 128x1024 image is slow
    // under the sanitizers: convert the first scan of the small layouts only.
    if (emitted++ == 0 && scan.range.size() <= 32 * 1024) {
      const rim::RangeImage image = rim::toRangeImage(scan, chosen.model);
      if (image.range.size() != scan.range.size()) std::abort();
      if (chosen.metadata.profile == rim::UdpProfile::kRng19Rfl8Sig16Nir16Dual)
        rim::toRangeImage(scan, chosen.model, rim::ReturnIndex::kSecond);
    }
    // Whatever the bytes, missing columns hold no data.
    for (int column = 0; column < scan.columns; ++column)
      if (scan.status[column] == 0 && scan.timestamp_ns[column] != 0) std::abort();
  });
  const std::size_t packet_size = batcher.format().packetSize();
  std::size_t at = 1;
  // Copies make every packet its own allocation, so ASan sees any overread.
  std::vector<uint8_t> packet;
  while (at < size) {
    const uint8_t operation = data[at++];
    std::size_t length = packet_size;
    switch (operation % 4) {
      case 0: break;
      case 1:
        if (size - at < 2) return 0;
        length = data[at] | static_cast<std::size_t>(data[at + 1]) << 8;
        at += 2;
        break;
      case 2: batcher.flush(); continue;
      case 3: length = packet_size - 1; break;
    }
    length = std::min(length, size - at);
    packet.assign(data + at, data + at + length);
    batcher.addPacket(packet.data(), packet.size());
    at += length;
  }
  batcher.flush();
  const rim::BatcherStatistics& statistics = batcher.statistics();
  if (statistics.scans != emitted) std::abort();
  return 0;
}
