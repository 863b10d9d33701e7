// Scans back into packets: the real captures re-encoded byte for byte (but for
// the bits a LidarScan does not hold), decode(encode(scan)) == scan for every
// profile and size, column windows, pcap captures written and read back, and
// the other simulator outputs: pose files, KITTI scans, the seen surface sample.
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/io/pcap_writer.h"
#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/ouster_packet_encoder.h"
#include "range_image_mapping/scan_batcher.h"
#include "range_image_mapping/simulation/surface_sampler.h"

#include "capture_packets.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iostream>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace range_image_mapping {
namespace {

using test::Packet;

// ------------------------------------------------------------ helpers


using test::decodeCapture;
using test::lidarPackets;

// Packets through a fresh batcher, as the front end reads them.
std::vector<LidarScan> decodePackets(const std::vector<Packet>& packets, const OusterMetadata& metadata) {
  std::vector<LidarScan> scans;
  ScanBatcher batcher(metadata, [&](const LidarScan& scan) { scans.push_back(scan); });
  for (const Packet& packet : packets) batcher.addPacket(packet.data(), packet.size());
  batcher.flush();
  return scans;
}

// Field by field, naming the first difference.
::testing::AssertionResult sameScan(const LidarScan& expected, const LidarScan& actual) {
  if (expected.rows != actual.rows || expected.columns != actual.columns)
    return ::testing::AssertionFailure() << "size " << actual.rows << "x" << actual.columns
                                         << " instead of " << expected.rows << "x" << expected.columns;
  if (expected.frame_id != actual.frame_id)
    return ::testing::AssertionFailure() << "frame id " << actual.frame_id << " instead of "
                                         << expected.frame_id;
  const auto compare = [&](const auto& a, const auto& b, const char* name) -> std::string {
    if (a.size() != b.size())
      return std::string(name) + " has " + std::to_string(b.size()) + " entries instead of " +
             std::to_string(a.size());
    for (std::size_t i = 0; i < a.size(); ++i)
      if (a[i] != b[i])
        return std::string(name) + "[" + std::to_string(i) + "] is " + std::to_string(b[i]) +
               " instead of " + std::to_string(a[i]);
    return "";
  };
  for (const std::string& difference :
       {compare(expected.range, actual.range, "range"), compare(expected.range2, actual.range2, "range2"),
        compare(expected.reflectivity, actual.reflectivity, "reflectivity"),
        compare(expected.reflectivity2, actual.reflectivity2, "reflectivity2"),
        compare(expected.signal, actual.signal, "signal"), compare(expected.signal2, actual.signal2, "signal2"),
        compare(expected.near_ir, actual.near_ir, "near_ir"),
        compare(expected.timestamp_ns, actual.timestamp_ns, "timestamp_ns"),
        compare(expected.measurement_id, actual.measurement_id, "measurement_id"),
        compare(expected.status, actual.status, "status"),
        compare(expected.encoder_count, actual.encoder_count, "encoder_count")})
    if (!difference.empty()) return ::testing::AssertionFailure() << difference;
  return ::testing::AssertionSuccess();
}

// Hand-made metadata of any size and profile (no JSON needed by PacketFormat).
OusterMetadata syntheticMetadata(UdpProfile profile, int rows, int columns,
                                 std::array<int, 2> window = {0, -1}, int columns_per_packet = 16) {
  OusterMetadata metadata;
  metadata.intrinsics = LidarIntrinsics::synthetic(rows, columns, 0.3, -0.3);
  if (window[1] >= 0) metadata.intrinsics.column_window = window;
  metadata.profile = profile;
  metadata.columns_per_packet = columns_per_packet;
  metadata.columns_per_frame = columns;
  metadata.pixels_per_column = rows;
  metadata.serial = "992210000957";
  metadata.initialization_id = 5431293;
  return metadata;
}

// A scan with random values the profile can carry, the valid columns those the
// window holds; every invalid column all zero, as the decoder leaves them.
LidarScan randomScan(const OusterMetadata& metadata, uint32_t seed) {
  const PacketFormat format(metadata);
  const UdpProfile profile = metadata.profile;
  LidarScan scan(format.rows(), format.columns(), profile);
  std::mt19937 random(seed);
  const auto uniform = [&](uint32_t maximum) {
    return std::uniform_int_distribution<uint32_t>(0, maximum)(random);
  };
  scan.frame_id = uniform(0xFFFF);
  const uint32_t max_range = maxRangeMillimetres(profile);
  const bool rng15 = profile == UdpProfile::kRng15Rfl8Nir8;
  const uint64_t start_ns = 1000000000ull * uniform(4000000) + uniform(999999999);
  for (int column = 0; column < scan.columns; ++column) {
    if (!format.columnInWindow(column)) continue;
    scan.status[column] = validColumnStatus(profile);
    scan.measurement_id[column] = static_cast<uint16_t>(column);
    scan.timestamp_ns[column] = start_ns + 97656ull * column + uniform(500);
    if (profile == UdpProfile::kLegacy) scan.encoder_count[column] = legacyEncoderCount(column, scan.columns);
    for (int row = 0; row < scan.rows; ++row) {
      const std::size_t i = static_cast<std::size_t>(row) * scan.columns + column;
      const auto range = [&] {
        if (uniform(9) == 0) return 0u;  // no return
        const uint32_t value = uniform(max_range);
        return rng15 ? value / 8 * 8 : value;
      };
      scan.range[i] = range();
      scan.reflectivity[i] = static_cast<uint8_t>(uniform(255));
      scan.near_ir[i] = static_cast<uint16_t>(rng15 ? uniform(255) * 16 : uniform(0xFFFF));
      if (!scan.signal.empty()) scan.signal[i] = static_cast<uint16_t>(uniform(0xFFFF));
      if (!scan.range2.empty()) {
        scan.range2[i] = range();
        scan.reflectivity2[i] = static_cast<uint8_t>(uniform(255));
        scan.signal2[i] = static_cast<uint16_t>(uniform(0xFFFF));
      }
    }
  }
  return scan;
}

std::string temporaryPath(const std::string& name) {
  const std::filesystem::path directory =
      std::filesystem::temp_directory_path() / ("rim_outputs_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(directory);
  return (directory / name).string();
}

// ------------------------------------------------------------ real captures, byte for byte

// Bits a LidarScan does not hold, cleared in both packets before comparing:
// pixel flags, the window byte, header fields past the serial number (alert
// flags, countdowns), the footer (filler or CRC), and the timestamp of columns
// the decoder never stores (status 0).
void clearUnheldBits(Packet& packet, const PacketFormat& format, const Packet& reference) {
  const UdpProfile profile = format.profile();
  const bool legacy = profile == UdpProfile::kLegacy;
  const std::size_t header = legacy ? 0 : 32;
  const std::size_t pixel_bytes = (format.packetSize() - (legacy ? 0 : 64)) / format.columnsPerPacket();
  const std::size_t column_header = legacy ? 16 : 12;
  const std::size_t pixel_size = (pixel_bytes - column_header - (legacy ? 4 : 0)) / format.rows();
  if (!legacy) {
    std::fill(packet.begin() + 12, packet.begin() + 32, 0);
    std::fill(packet.end() - 32, packet.end(), 0);
  }
  for (int c = 0; c < format.columnsPerPacket(); ++c) {
    uint8_t* column = packet.data() + header + c * pixel_bytes;
    const uint8_t* reference_column = reference.data() + header + c * pixel_bytes;
    uint32_t status;
    if (legacy)
      std::memcpy(&status, reference_column + column_header + format.rows() * pixel_size, 4);
    else
      status = static_cast<uint32_t>(reference_column[10] | reference_column[11] << 8) & 1u;
    if (status == 0) std::fill(column, column + 8, 0);
    for (int row = 0; row < format.rows(); ++row) {
      uint8_t* pixel = column + column_header + row * pixel_size;
      switch (profile) {
        case UdpProfile::kLegacy:  // range 20 bits
          pixel[2] &= 0x0F, pixel[3] = 0, pixel[5] = 0, pixel[10] = 0, pixel[11] = 0;
          break;
        case UdpProfile::kRng19Rfl8Sig16Nir16:  // range 19 bits
          pixel[2] &= 0x07, pixel[3] = 0, pixel[5] = 0, pixel[10] = 0, pixel[11] = 0;
          break;
        case UdpProfile::kRng19Rfl8Sig16Nir16Dual:  // reflectivity in the top byte
          pixel[2] &= 0x07, pixel[6] &= 0x07, pixel[14] = 0, pixel[15] = 0;
          break;
        case UdpProfile::kRng15Rfl8Nir8:  // bit 15 is a flag
          pixel[1] &= 0x7F;
          break;
      }
    }
  }
}

struct RealCapture {
  const char* pcap;
  const char* metadata;
  std::size_t scans;
};

void PrintTo(const RealCapture& capture, std::ostream* out) { *out << capture.pcap; }

class RealCaptureTest : public ::testing::TestWithParam<RealCapture> {};

TEST_P(RealCaptureTest, ReencodesByteForByteAndDecodesBack) {
  const RealCapture& capture = GetParam();
  RIM_REQUIRE_DATA(pcap_path, std::string("ouster-pcaps/") + capture.pcap);
  RIM_REQUIRE_DATA(metadata_path, std::string("ouster-pcaps/") + capture.metadata);
  const OusterMetadata metadata = loadOusterMetadata(metadata_path);
  const std::vector<LidarScan> scans = decodeCapture(pcap_path, metadata);
  ASSERT_EQ(scans.size(), capture.scans);
  const std::vector<Packet> originals = lidarPackets(pcap_path, metadata);

  const OusterPacketEncoder encoder(metadata);
  std::vector<Packet> encoded;
  for (const LidarScan& scan : scans) {
    const std::vector<Packet> packets = encoder.encode(scan);
    encoded.insert(encoded.end(), packets.begin(), packets.end());
  }
  ASSERT_EQ(encoded.size(), originals.size());
  const PacketFormat& format = encoder.format();
  std::size_t identical_before_masking = 0;
  for (std::size_t p = 0; p < originals.size(); ++p) {
    identical_before_masking += encoded[p] == originals[p];
    if (format.profile() != UdpProfile::kLegacy) {
      // Type, frame id, initialization id and serial number come from scan and metadata.
      ASSERT_TRUE(std::equal(originals[p].begin(), originals[p].begin() + 12, encoded[p].begin()))
          << "packet " << p << " header";
      uint64_t crc;
      std::memcpy(&crc, encoded[p].data() + encoded[p].size() - 8, 8);
      ASSERT_EQ(crc, crc64(encoded[p].data(), encoded[p].size() - 8)) << "packet " << p;
    }
    Packet original = originals[p], mine = encoded[p];
    clearUnheldBits(original, format, originals[p]);
    clearUnheldBits(mine, format, originals[p]);
    ASSERT_TRUE(original == mine) << "packet " << p << " differs beyond the bits a scan does not hold";
  }
  std::cout << capture.pcap << ": " << originals.size() << " packets equal, " << identical_before_masking
            << " also in flag bits, header tail and footer\n";

  // And back: the same scans, every field.
  const std::vector<LidarScan> decoded = decodePackets(encoded, metadata);
  ASSERT_EQ(decoded.size(), scans.size());
  for (std::size_t i = 0; i < scans.size(); ++i) EXPECT_TRUE(sameScan(scans[i], decoded[i])) << i;
  if (metadata.profile == UdpProfile::kLegacy)
    for (int column = 0; column < scans[0].columns; ++column)
      ASSERT_EQ(scans[0].encoder_count[column], legacyEncoderCount(column, scans[0].columns)) << column;
}

INSTANTIATE_TEST_SUITE_P(
    Captures, RealCaptureTest,
    ::testing::Values(
        RealCapture{"OS-1-32-G_v2.1.1_1024x10.pcap", "OS-1-32-G_v2.1.1_1024x10.json", 1},        // LEGACY
        RealCapture{"OS-2-128-U1_v2.3.0_1024x10.pcap", "OS-2-128-U1_v2.3.0_1024x10.json", 1},    // RNG19
        RealCapture{"OS-0-32-U1_v2.2.0_1024x10.pcap", "OS-0-32-U1_v2.2.0_1024x10.json", 1},      // DUAL
        RealCapture{"OS-1-128_v2.3.0_1024x10_lb_n3.pcap", "OS-1-128_v2.3.0_1024x10.json", 3},    // RNG15
        RealCapture{"crc_test.pcap", "crc_test.json", 2},  // 512 columns, partial second frame
        RealCapture{"windowed_frame1.pcap", "windowed_frame1_0.json", 1},  // window [1, 256]
        RealCapture{"windowed_frame2.pcap", "windowed_frame2_0.json", 1}),  // window [370, 85]
    [](const ::testing::TestParamInfo<RealCapture>& info) {
      std::string name = std::string(info.param.pcap);
      name = name.substr(0, name.find('.'));
      std::replace_if(name.begin(), name.end(), [](char c) { return !std::isalnum(c); }, '_');
      return name;
    });

TEST(OusterPacketEncoder, Crc64MatchesFirmware3Footer) {
  RIM_REQUIRE_DATA(pcap_path, "ouster-pcaps/crc_test.pcap");
  RIM_REQUIRE_DATA(metadata_path, "ouster-pcaps/crc_test.json");
  const std::vector<Packet> packets = lidarPackets(pcap_path, loadOusterMetadata(metadata_path));
  ASSERT_FALSE(packets.empty());
  for (const Packet& packet : packets) {
    uint64_t stored;
    std::memcpy(&stored, packet.data() + packet.size() - 8, 8);
    ASSERT_EQ(crc64(packet.data(), packet.size() - 8), stored);
  }
  // The CRC-64/XZ check value.
  const char* check = "123456789";
  EXPECT_EQ(crc64(reinterpret_cast<const uint8_t*>(check), 9), 0x995DC9BBDF1939FAull);
}

TEST(OusterPacketEncoder, MetadataInitializationIdIsRead) {
  RIM_REQUIRE_DATA(flat_path, "ouster-pcaps/OS-2-128-U1_v2.3.0_1024x10.json");
  RIM_REQUIRE_DATA(nested_path, "ouster-pcaps/crc_test.json");
  EXPECT_EQ(loadOusterMetadata(flat_path).initialization_id, 5431293u);
  EXPECT_EQ(loadOusterMetadata(nested_path).initialization_id, 11394290u);
}

// ------------------------------------------------------------ synthetic scans

struct SyntheticCase {
  UdpProfile profile;
  int rows;
  int columns;
};

void PrintTo(const SyntheticCase& test_case, std::ostream* out) {
  *out << toString(test_case.profile) << " " << test_case.rows << "x" << test_case.columns;
}

class SyntheticRoundTripTest : public ::testing::TestWithParam<SyntheticCase> {};

TEST_P(SyntheticRoundTripTest, DecodeOfEncodeIsTheScan) {
  const SyntheticCase& test_case = GetParam();
  const OusterMetadata metadata = syntheticMetadata(test_case.profile, test_case.rows, test_case.columns);
  const OusterPacketEncoder encoder(metadata);
  const LidarScan scan = randomScan(metadata, test_case.rows * 7919u + test_case.columns);
  std::size_t packets = 0;
  uint64_t previous_timestamp = 0;
  std::vector<Packet> encoded;
  encoder.encode(scan, [&](const uint8_t* packet, std::size_t size, uint64_t timestamp_ns) {
    EXPECT_EQ(size, encoder.format().packetSize());
    EXPECT_GT(timestamp_ns, previous_timestamp);  // packets leave in firing order
    previous_timestamp = timestamp_ns;
    encoded.emplace_back(packet, packet + size);
    ++packets;
  });
  EXPECT_EQ(packets, std::size_t(test_case.columns / 16));
  const std::vector<LidarScan> decoded = decodePackets(encoded, metadata);
  ASSERT_EQ(decoded.size(), 1u);
  EXPECT_TRUE(sameScan(scan, decoded[0]));
}

std::vector<SyntheticCase> allSyntheticCases() {
  std::vector<SyntheticCase> cases;
  for (const UdpProfile profile : {UdpProfile::kLegacy, UdpProfile::kRng19Rfl8Sig16Nir16,
                                   UdpProfile::kRng19Rfl8Sig16Nir16Dual, UdpProfile::kRng15Rfl8Nir8})
    for (const int rows : {16, 32, 64, 128})
      for (const int columns : {512, 1024, 2048}) cases.push_back({profile, rows, columns});
  return cases;
}

INSTANTIATE_TEST_SUITE_P(Profiles, SyntheticRoundTripTest, ::testing::ValuesIn(allSyntheticCases()),
                         [](const ::testing::TestParamInfo<SyntheticCase>& info) {
                           std::string name = toString(info.param.profile);
                           return name + "_" + std::to_string(info.param.rows) + "x" +
                                  std::to_string(info.param.columns);
                         });

TEST(OusterPacketEncoder, ColumnWindowsSendOnlyTheirPackets) {
  struct Window {
    std::array<int, 2> columns;
    std::vector<int> first_columns;  // of the packets sent
  };
  const std::vector<Window> windows = {
      {{1, 256}, {0, 16, 32, 48, 64, 80, 96, 112, 128, 144, 160, 176, 192, 208, 224, 240, 256}},
      {{370, 85}, {0, 16, 32, 48, 64, 80, 368, 384, 400, 416, 432, 448, 464, 480, 496}},  // wraps
      {{496, 15}, {0, 496}},
      {{100, 100}, {96}}};
  for (const UdpProfile profile : {UdpProfile::kLegacy, UdpProfile::kRng19Rfl8Sig16Nir16})
    for (const Window& window : windows) {
      const OusterMetadata metadata = syntheticMetadata(profile, 32, 512, window.columns);
      const OusterPacketEncoder encoder(metadata);
      const LidarScan scan = randomScan(metadata, 11);
      std::vector<int> first_columns;
      std::vector<Packet> packets;
      encoder.encode(scan, [&](const uint8_t* packet, std::size_t size, uint64_t) {
        packets.emplace_back(packet, packet + size);
        uint16_t measurement_id;
        std::memcpy(&measurement_id, packet + (profile == UdpProfile::kLegacy ? 8 : 40), 2);
        first_columns.push_back(measurement_id);
      });
      EXPECT_EQ(first_columns, window.first_columns) << window.columns[0] << ".." << window.columns[1];
      std::vector<LidarScan> decoded;
      ScanBatcher counting(metadata, [&](const LidarScan& s) { decoded.push_back(s); });
      for (const Packet& packet : packets) counting.addPacket(packet.data(), packet.size());
      // The window completes with the last packet: no flush needed.
      ASSERT_EQ(decoded.size(), 1u);
      EXPECT_EQ(counting.statistics().incomplete_scans, 0u);
      EXPECT_TRUE(sameScan(scan, decoded[0]));
    }
}

TEST(OusterPacketEncoder, OtherPacketSizesAndFrameIdWrap) {
  // 8 and 32 columns per packet; a frame id past 16 bits is sent modulo 2^16.
  for (const int per_packet : {8, 32}) {
    const OusterMetadata metadata =
        syntheticMetadata(UdpProfile::kRng19Rfl8Sig16Nir16, 64, 1024, {0, -1}, per_packet);
    const OusterPacketEncoder encoder(metadata);
    LidarScan scan = randomScan(metadata, 5);
    const std::vector<Packet> packets = encoder.encode(scan);
    EXPECT_EQ(packets.size(), std::size_t(1024 / per_packet));
    scan.frame_id = 70000;
    const std::vector<LidarScan> decoded = decodePackets(encoder.encode(scan), metadata);
    ASSERT_EQ(decoded.size(), 1u);
    EXPECT_EQ(decoded[0].frame_id, 70000u % 65536u);
  }
}

TEST(OusterPacketEncoder, MissingColumnsAndLostPackets) {
  const OusterMetadata metadata = syntheticMetadata(UdpProfile::kRng19Rfl8Sig16Nir16, 16, 512);
  const OusterPacketEncoder encoder(metadata);
  LidarScan scan = randomScan(metadata, 3);
  // Columns 16..31 lost (one packet), column 40 invalid within a sent packet.
  const auto clearColumn = [&](int column) {
    scan.status[column] = 0;
    scan.timestamp_ns[column] = 0;
    scan.measurement_id[column] = 0;
    for (int row = 0; row < scan.rows; ++row) {
      const std::size_t i = std::size_t(row) * scan.columns + column;
      scan.range[i] = scan.reflectivity[i] = scan.signal[i] = scan.near_ir[i] = 0;
    }
  };
  for (int column = 16; column < 32; ++column) clearColumn(column);
  clearColumn(40);
  const std::vector<Packet> packets = encoder.encode(scan);
  EXPECT_EQ(packets.size(), 512u / 16 - 1);
  const std::vector<LidarScan> decoded = decodePackets(packets, metadata);
  ASSERT_EQ(decoded.size(), 1u);
  EXPECT_TRUE(sameScan(scan, decoded[0]));
}

TEST(OusterPacketEncoder, ValuesTheProfileCannotCarryAreErrors) {
  const OusterMetadata rng19 = syntheticMetadata(UdpProfile::kRng19Rfl8Sig16Nir16, 16, 512);
  LidarScan scan = randomScan(rng19, 1);
  scan.range[3 * 512 + 7] = 1u << 19;
  try {
    OusterPacketEncoder(rng19).encode(scan, [](const uint8_t*, std::size_t, uint64_t) {
      FAIL() << "a packet was handed out before the error";
    });
    FAIL() << "no error";
  } catch (const PacketEncodingError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("range 524288 at row 3, column 7 exceeds 524287 mm"), std::string::npos)
        << message;
  }
  // quantizeForProfile turns it into "no return".
  quantizeForProfile(scan, UdpProfile::kRng19Rfl8Sig16Nir16);
  EXPECT_EQ(scan.range[3 * 512 + 7], 0u);
  EXPECT_NO_THROW(OusterPacketEncoder(rng19).encode(scan));

  const OusterMetadata rng15 = syntheticMetadata(UdpProfile::kRng15Rfl8Nir8, 16, 512);
  LidarScan low = randomScan(rng15, 2);
  low.range[5] = 12345;  // not a multiple of 8 mm
  low.near_ir[9] = 100;  // not a multiple of 16
  EXPECT_THROW(OusterPacketEncoder(rng15).encode(low), PacketEncodingError);
  quantizeForProfile(low, UdpProfile::kRng15Rfl8Nir8);
  EXPECT_EQ(low.range[5], 12344u);
  EXPECT_EQ(low.near_ir[9], 96u);
  const std::vector<LidarScan> decoded = decodePackets(OusterPacketEncoder(rng15).encode(low), rng15);
  ASSERT_EQ(decoded.size(), 1u);
  EXPECT_TRUE(sameScan(low, decoded[0]));

  // A scan made for another size or profile.
  EXPECT_THROW(OusterPacketEncoder(rng19).encode(LidarScan(16, 1024, UdpProfile::kRng19Rfl8Sig16Nir16)),
               PacketEncodingError);
  EXPECT_THROW(OusterPacketEncoder(rng19).encode(LidarScan(16, 512, UdpProfile::kRng15Rfl8Nir8)),
               PacketEncodingError);
  // Metadata the packets cannot describe.
  EXPECT_THROW(OusterPacketEncoder(syntheticMetadata(UdpProfile::kLegacy, 16, 520)), std::invalid_argument);
  OusterMetadata bad_serial = rng19;
  bad_serial.serial = "OS-1-XYZ";
  EXPECT_THROW(OusterPacketEncoder{bad_serial}, std::invalid_argument);
  EXPECT_THROW(legacyEncoderCount(1024, 1024), std::invalid_argument);
}

// ------------------------------------------------------------ pcap

TEST(PcapWriter, CapturesReadBackIntoTheSameScans) {
  for (const UdpProfile profile : {UdpProfile::kLegacy, UdpProfile::kRng19Rfl8Sig16Nir16}) {
    OusterMetadata metadata = syntheticMetadata(profile, 128, 1024);
    metadata.udp_port_lidar = 7777;
    std::vector<LidarScan> scans;
    for (uint32_t i = 0; i < 3; ++i) {
      scans.push_back(randomScan(metadata, 100 + i));
      scans.back().frame_id = 65534 + i;  // crosses the 16-bit wrap
    }
    for (const std::size_t mtu : {std::size_t{0}, std::size_t{1500}}) {
      const std::string path = temporaryPath("scans_" + std::string(toString(profile)) + "_" +
                                             std::to_string(mtu) + ".pcap");
      io::OusterPcapWriter writer(path, metadata, io::PcapWriterOptions{mtu});
      for (const LidarScan& scan : scans) EXPECT_EQ(writer.writeScan(scan), 64u);
      writer.close();

      io::OusterPcapStatistics statistics;
      const std::vector<LidarScan> decoded = decodeCapture(path, metadata, &statistics);
      EXPECT_FALSE(statistics.classified_by_size);  // found on the metadata's port
      EXPECT_EQ(statistics.lidar_datagrams, 3u * 64u);
      EXPECT_EQ(statistics.pcap.reassembled, mtu == 0 ? 0u : 3u * 64u);
      EXPECT_EQ(statistics.pcap.skipped_malformed, 0u);
      ASSERT_EQ(decoded.size(), 3u);
      for (std::size_t i = 0; i < 3; ++i) {
        LidarScan expected = scans[i];
        expected.frame_id %= 65536;
        EXPECT_TRUE(sameScan(expected, decoded[i])) << i << " mtu " << mtu;
      }

      // Records: Ethernet + IPv4 with a valid header checksum, timestamps of the packets.
      io::PcapReader reader(path);
      io::UdpDatagram datagram;
      ASSERT_TRUE(reader.next(datagram));
      EXPECT_EQ(datagram.source_address, 0x7F000001u);
      EXPECT_EQ(datagram.destination_port, 7777);
      EXPECT_EQ(datagram.timestamp_ns / 1000, scans[0].timestamp_ns[15] / 1000);
    }
  }
}

TEST(PcapWriter, HeadersAndChecksums) {
  const std::string path = temporaryPath("checksums.pcap");
  const std::vector<uint8_t> payload = {1, 2, 3, 4, 5};
  {
    io::PcapWriter writer(path);
    io::UdpDatagram datagram;
    datagram.payload = payload.data();
    datagram.size = payload.size();
    datagram.source_address = 0xC0A80001;
    datagram.destination_address = 0xC0A80002;
    datagram.source_port = 1234;
    datagram.destination_port = 7502;
    datagram.timestamp_ns = 1234567890123456789ull;
    writer.write(datagram);
    writer.close();
    EXPECT_EQ(writer.recordsWritten(), 1u);
  }
  std::ifstream file(path, std::ios::binary);
  const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  ASSERT_EQ(bytes.size(), 24u + 16u + 14u + 20u + 8u + 5u);
  EXPECT_EQ(bytes[0], 0xD4);  // little-endian, microseconds
  const auto sum = [&](std::size_t begin, std::size_t end, uint32_t total) {
    for (std::size_t i = begin; i < end; i += 2)
      total += uint32_t(bytes[i]) << 8 | (i + 1 < end ? bytes[i + 1] : 0);
    while (total >> 16) total = (total & 0xFFFF) + (total >> 16);
    return total;
  };
  const std::size_t ip = 24 + 16 + 14;
  EXPECT_EQ(sum(ip, ip + 20, 0), 0xFFFFu);  // IPv4 header checksum
  const uint32_t pseudo = sum(ip + 12, ip + 20, 17 + 13);  // addresses, protocol, UDP length
  EXPECT_EQ(sum(ip + 20, bytes.size(), pseudo), 0xFFFFu);  // UDP checksum
  uint32_t seconds, microseconds;
  std::memcpy(&seconds, bytes.data() + 24, 4);
  std::memcpy(&microseconds, bytes.data() + 28, 4);
  EXPECT_EQ(seconds, 1234567890u);
  EXPECT_EQ(microseconds, 123456u);

  io::PcapWriter writer(temporaryPath("too_large.pcap"));
  const std::vector<uint8_t> large(65508);
  io::UdpDatagram datagram;
  datagram.payload = large.data();
  datagram.size = large.size();
  EXPECT_THROW(writer.write(datagram), io::PcapError);
  EXPECT_THROW(io::PcapWriter(temporaryPath("x.pcap"), io::PcapWriterOptions{40}), std::invalid_argument);
  EXPECT_THROW(io::PcapWriter("/nonexistent/directory/x.pcap"), io::PcapError);
}

// ------------------------------------------------------------ pose files

std::vector<io::StampedPose> randomPoses(int count, uint32_t seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> uniform(-100.0, 100.0);
  std::vector<io::StampedPose> poses;
  for (int i = 0; i < count; ++i) {
    io::StampedPose stamped;
    stamped.time_s = 1700000000.0 + 0.1 * i + 1e-9 * (i % 7);
    stamped.pose.linear() =
        Eigen::Quaterniond(Eigen::Vector4d(uniform(random), uniform(random), uniform(random),
                                           uniform(random)).normalized())
            .toRotationMatrix();
    stamped.pose.translation() = Eigen::Vector3d(uniform(random), uniform(random), uniform(random));
    poses.push_back(stamped);
  }
  return poses;
}

void expectSamePoses(const std::vector<io::StampedPose>& expected,
                     const std::vector<io::StampedPose>& actual, double tolerance) {
  ASSERT_EQ(expected.size(), actual.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    EXPECT_NEAR(expected[i].time_s, actual[i].time_s, 1e-6) << i;
    EXPECT_TRUE(expected[i].pose.matrix().isApprox(actual[i].pose.matrix(), tolerance)) << i;
  }
}

TEST(PoseFile, TumAndKittiRoundTrip) {
  const std::vector<io::StampedPose> poses = randomPoses(50, 9);
  io::PoseFileInfo info;
  info.frame = "os_lidar";
  info.comment = "test";
  const std::string tum = temporaryPath("poses_tum.txt");
  io::writeTumPoses(tum, poses, info);
  expectSamePoses(poses, io::readTumPoses(tum), 1e-8);
  expectSamePoses(poses, io::readPoseFile(tum), 1e-8);
  std::ifstream tum_file(tum);
  std::string first_line;
  std::getline(tum_file, first_line);
  EXPECT_NE(first_line.find("os_lidar"), std::string::npos) << first_line;

  const std::string kitti = temporaryPath("poses_kitti.txt");
  io::writeKittiPosesWithTimes(kitti, poses, info);
  const io::KittiPoseFilePaths paths = io::kittiPoseFilePaths(kitti);
  EXPECT_EQ(paths.times, temporaryPath("poses_kitti_times.txt"));
  // The poses file stays plain KITTI, readable by the devkit and io::readKittiPoses.
  EXPECT_EQ(io::readKittiPoses(kitti).size(), poses.size());
  expectSamePoses(poses, io::readKittiPosesWithTimes(kitti), 1e-8);
  expectSamePoses(poses, io::readPoseFile(kitti), 1e-8);
  std::ifstream sidecar(paths.sidecar);
  std::stringstream sidecar_text;
  sidecar_text << sidecar.rdbuf();
  EXPECT_NE(sidecar_text.str().find("\"frame\" : \"os_lidar\""), std::string::npos) << sidecar_text.str();
  EXPECT_NE(sidecar_text.str().find("poses_kitti_times.txt"), std::string::npos);

  // The lb_n3 reference poses, with made-up times.
  const std::string reference = test::dataFile("ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt");
  if (!reference.empty()) {
    const std::vector<Eigen::Isometry3d> matrices = io::readKittiPoses(reference);
    std::vector<io::StampedPose> stamped;
    for (std::size_t i = 0; i < matrices.size(); ++i) stamped.push_back({0.1 * i, matrices[i]});
    const std::string copy = temporaryPath("lb_n3.txt");
    io::writeKittiPosesWithTimes(copy, stamped);
    expectSamePoses(stamped, io::readPoseFile(copy), 1e-8);
  }
}

TEST(PoseFile, ErrorsNameTheLine) {
  const auto write = [](const std::string& name, const std::string& text) {
    const std::string path = temporaryPath(name);
    std::ofstream(path) << text;
    return path;
  };
  const auto message = [](const auto& call) {
    try {
      call();
    } catch (const io::PoseFileError& error) {
      return std::string(error.what());
    }
    return std::string("no error");
  };
  const std::string qw_first = write("qw_first.txt", "# comment\n0 1 2 3 0 0 0 1\n1 1 2 3 1 0 0 0.5\n");
  EXPECT_NE(message([&] { io::readTumPoses(qw_first); }).find("line 3"), std::string::npos);
  const std::string seven = write("seven.txt", "0 1 2 3 0 0 0\n");
  EXPECT_NE(message([&] { io::readPoseFile(seven); }).find("neither TUM"), std::string::npos);
  const std::string words = write("words.txt", "0 1 2 x 0 0 0 1\n");
  EXPECT_NE(message([&] { io::readTumPoses(words); }).find("line 1"), std::string::npos);
  const std::string kitti = write("no_times.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n");
  EXPECT_NE(message([&] { io::readPoseFile(kitti); }).find("no times file"), std::string::npos);
  write("counts_times.txt", "0\n1\n");
  const std::string counts = write("counts.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n");
  EXPECT_NE(message([&] { io::readPoseFile(counts); }).find("2 times"), std::string::npos);
  EXPECT_NE(message([&] { io::readTumPoses(temporaryPath("missing.txt")); }).find("cannot open"),
            std::string::npos);
}

TEST(PoseFile, ChangeOfFrameAndColumnTimes) {
  // Lidar poses into sensor poses: the same world point either way.
  const std::vector<io::StampedPose> lidar = randomPoses(5, 4);
  Eigen::Isometry3d lidar_to_sensor = Eigen::Isometry3d::Identity();
  lidar_to_sensor.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  lidar_to_sensor.translation() = Eigen::Vector3d(0, 0, 0.03618);
  const std::vector<io::StampedPose> sensor = io::changePoseFrame(lidar, lidar_to_sensor);
  const Eigen::Vector3d point_lidar(1.0, -2.0, 0.5);
  for (std::size_t i = 0; i < lidar.size(); ++i)
    EXPECT_TRUE((sensor[i].pose * (lidar_to_sensor * point_lidar)).isApprox(lidar[i].pose * point_lidar, 1e-12));

  const std::string path = temporaryPath("column_times.txt");
  std::vector<std::vector<uint64_t>> scans(3, std::vector<uint64_t>(1024));
  for (std::size_t s = 0; s < scans.size(); ++s)
    for (std::size_t u = 0; u < 1024; ++u) scans[s][u] = u == 5 ? 0 : 991587364520ull + s * 100000000 + u * 97656;
  io::ColumnTimesWriter writer(path);
  for (const auto& scan : scans) writer.write(scan);
  EXPECT_THROW(writer.write(std::vector<uint64_t>(512)), std::invalid_argument);
  writer.close();
  EXPECT_EQ(io::readColumnTimes(path), scans);
}

// ------------------------------------------------------------ KITTI scans

TEST(KittiWriter, VelodyneScanRoundTrip) {
  std::mt19937 random(3);
  std::normal_distribution<float> normal(0.0f, 20.0f);
  std::vector<Eigen::Vector3f> points(1000);
  std::vector<float> intensities(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    points[i] = Eigen::Vector3f(normal(random), normal(random), normal(random));
    intensities[i] = std::abs(normal(random)) / 100.0f;
  }
  const std::string path = temporaryPath("000000.bin");
  io::writeKittiVelodyne(path, points, intensities);
  EXPECT_EQ(std::filesystem::file_size(path), points.size() * 16);
  const PointCloudInput cloud = io::readKittiVelodyne(path);
  ASSERT_EQ(cloud.points.size(), points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    ASSERT_EQ(cloud.points[i], points[i]) << i;  // bit for bit
    ASSERT_EQ(cloud.intensity[i], intensities[i]) << i;
  }
  io::writeKittiVelodyne(path, points, {});
  EXPECT_EQ(io::readKittiVelodyne(path).intensity[7], 0.0f);
  EXPECT_THROW(io::writeKittiVelodyne(path, points, std::vector<float>(3)), std::invalid_argument);
  EXPECT_THROW(io::writeKittiVelodyne("/nonexistent/directory/0.bin", points, {}), io::KittiFormatError);
}

// ------------------------------------------------------------ surface sample

// A 10 x 8 x 3 m room, as two triangles per wall.
TriangleMesh boxRoom() {
  TriangleMesh mesh;
  for (int i = 0; i < 8; ++i) mesh.vertices.emplace_back(i & 1 ? 10.0f : 0.0f, i & 2 ? 8.0f : 0.0f, i & 4 ? 3.0f : 0.0f);
  const int faces[6][4] = {{0, 1, 3, 2}, {4, 6, 7, 5}, {0, 4, 5, 1}, {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 5, 7, 3}};
  for (const auto& face : faces) {
    mesh.triangles.emplace_back(face[0], face[1], face[2]);
    mesh.triangles.emplace_back(face[0], face[2], face[3]);
  }
  return mesh;
}

TEST(SurfaceSampler, DenseAreaWeightedAndDeterministic) {
  const TriangleMesh room = boxRoom();
  SurfaceSampleOptions options;
  options.spacing_m = 0.05;
  const std::vector<Eigen::Vector3f> samples = sampleSurface(room, options);
  const double area = 2 * (10 * 8) + 2 * (10 * 3) + 2 * (8 * 3);
  EXPECT_NEAR(double(samples.size()), area / (0.05 * 0.05), 0.01 * area / (0.05 * 0.05));
  // Each wall gets its share of the area.
  const auto onFloor = [](const Eigen::Vector3f& p) { return std::abs(p.z()) < 1e-4f; };
  const double floor_count = double(std::count_if(samples.begin(), samples.end(), onFloor));
  EXPECT_NEAR(floor_count, 80 / (0.05 * 0.05), 0.02 * 80 / (0.05 * 0.05));
  for (const Eigen::Vector3f& p : samples)
    ASSERT_TRUE((p.array() >= -1e-4f).all() && p.x() <= 10.0001f && p.y() <= 8.0001f && p.z() <= 3.0001f);
  EXPECT_EQ(sampleSurface(room, options), samples);
  options.seed = 2;
  EXPECT_NE(sampleSurface(room, options), samples);

  options.spacing_m = 0;
  EXPECT_THROW(sampleSurface(room, options), std::invalid_argument);
  TriangleMesh broken = room;
  broken.triangles.emplace_back(0, 1, 8);
  options.spacing_m = 0.05;
  EXPECT_THROW(sampleSurface(broken, options), std::invalid_argument);
  EXPECT_THROW(simulation::SeenRegion(0.0), std::invalid_argument);
}

TEST(SurfaceSampler, KeepsOnlyWhatTheSensorSaw) {
  // Seen from inside, the sensor hit half the floor (x < 5) and the wall at x = 0.
  constexpr double kSeenDistance = 0.1;
  constexpr float kHitStep = 0.05f;
  std::vector<Eigen::Vector3f> hits;
  for (int x = 0; x <= 100; ++x)
    for (int y = 0; y <= 160; ++y) hits.emplace_back(x * kHitStep, y * kHitStep, 0.0f);
  for (int y = 0; y <= 160; ++y)
    for (int z = 0; z <= 60; ++z) hits.emplace_back(0.0f, y * kHitStep, z * kHitStep);
  hits.emplace_back(NAN, NAN, NAN);  // a missing return is skipped
  simulation::SeenRegion seen(kSeenDistance);
  seen.addHits(hits);

  const TriangleMesh room = boxRoom();
  SurfaceSampleOptions options;
  options.spacing_m = 0.02;
  const std::vector<Eigen::Vector3f> all = sampleSurface(room, options);
  const std::vector<Eigen::Vector3f> kept = simulation::sampleSeenSurface(room, seen, options);

  // Distance to the hit rectangles; the hits are a 5 cm grid on them.
  const auto distanceToSeen = [](const Eigen::Vector3f& p) {
    const Eigen::Vector3f floor(std::clamp(p.x(), 0.0f, 5.0f), std::clamp(p.y(), 0.0f, 8.0f), 0.0f);
    const Eigen::Vector3f wall(0.0f, std::clamp(p.y(), 0.0f, 8.0f), std::clamp(p.z(), 0.0f, 3.0f));
    return std::min((p - floor).norm(), (p - wall).norm());
  };
  const float grid_slack = kHitStep * std::sqrt(2.0f) / 2;
  for (const Eigen::Vector3f& p : kept)
    ASSERT_LE(distanceToSeen(p), (1 + std::sqrt(3.0)) * kSeenDistance) << p.transpose();
  // Every sample nearer to a hit than the seen distance is kept; kept ones are
  // samples of the full set (the same grid), so metrics can use either.
  const auto less = [](const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
    return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
  };
  std::vector<Eigen::Vector3f> sorted_kept = kept, sorted_all = all;
  std::sort(sorted_kept.begin(), sorted_kept.end(), less);
  std::sort(sorted_all.begin(), sorted_all.end(), less);
  std::size_t must_keep = 0;
  for (const Eigen::Vector3f& p : all) {
    if (distanceToSeen(p) >= kSeenDistance - grid_slack) continue;
    ++must_keep;
    ASSERT_TRUE(std::binary_search(sorted_kept.begin(), sorted_kept.end(), p, less)) << p.transpose();
  }
  for (const Eigen::Vector3f& p : kept)
    ASSERT_TRUE(std::binary_search(sorted_all.begin(), sorted_all.end(), p, less)) << p.transpose();
  // Seen: 40 m^2 of floor and 24 m^2 of wall, plus a rim of at most 0.27 m around them.
  EXPECT_GT(must_keep, std::size_t(64 / (0.02 * 0.02)));
  EXPECT_LT(kept.size(), std::size_t(73 / (0.02 * 0.02)));
  std::cout << "room: " << all.size() << " samples, " << kept.size() << " seen, " << seen.voxelCount()
            << " hit voxels\n";
}

}  // namespace
}  // namespace range_image_mapping
