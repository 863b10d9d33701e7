// The recordings rim reads, on real data: an Ouster packet bag gives the
// images of the same packets in a pcap (both driver generations' message
// type), a bag of PointCloud2 written from KITTI scans gives the images and
// the trajectory of the same scans as a folder, PCD files round-trip in ascii
// and binary, and malformed inputs give named errors.
#include "range_image_mapping/io/recording.h"

#include "error_text.h"
#include "md5.h"
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/io/pcap_writer.h"
#include "range_image_mapping/io/pcd.h"
#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/io/rosbag_reader.h"
#include "range_image_mapping/point_cloud_layout.h"
#include "rim_command.h"
#include "test_data.h"

#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/String.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>

// An Ouster PacketMsg ("uint8[] buf") under either driver generation's name,
// written without the Ouster packages.
namespace range_image_mapping::test {
template <int Generation>
struct PacketMessage {
  std::vector<uint8_t> buf;
};
}  // namespace range_image_mapping::test

namespace ros::message_traits {
template <int G>
struct MD5Sum<range_image_mapping::test::PacketMessage<G>> {
  static const char* value() { return "4f7b5949e76f86d01e96b0e33ba9b5e3"; }
  static const char* value(const range_image_mapping::test::PacketMessage<G>&) { return value(); }
};
template <int G>
struct DataType<range_image_mapping::test::PacketMessage<G>> {
  static const char* value() { return G == 1 ? "ouster_ros/PacketMsg" : "ouster_sensor_msgs/PacketMsg"; }
  static const char* value(const range_image_mapping::test::PacketMessage<G>&) { return value(); }
};
template <int G>
struct Definition<range_image_mapping::test::PacketMessage<G>> {
  static const char* value() { return "uint8[] buf\n"; }
  static const char* value(const range_image_mapping::test::PacketMessage<G>&) { return value(); }
};
}  // namespace ros::message_traits

namespace ros::serialization {
template <int G>
struct Serializer<range_image_mapping::test::PacketMessage<G>> {
  template <typename Stream, typename T>
  inline static void allInOne(Stream& stream, T message) {
    stream.next(message.buf);
  }
  ROS_DECLARE_ALLINONE_SERIALIZER
};
}  // namespace ros::serialization

namespace range_image_mapping {
namespace {

namespace fs = std::filesystem;
using test::contains;
using test::errorOf;

fs::path freshFolder(const std::string& name) {
  const fs::path folder = fs::temp_directory_path() / ("rim_recording_test_" + name + "_" + std::to_string(getpid()));
  fs::remove_all(folder);
  fs::create_directories(folder);
  return folder;
}

std::vector<RangeImage> scansOf(const io::Recording& recording, io::RecordingStatistics* statistics = nullptr) {
  std::vector<RangeImage> images;
  io::forEachScan(
      recording,
      [&](const RangeImage& image) {
        images.push_back(image);
        return true;
      },
      statistics);
  return images;
}

std::vector<RangeImage> scansOf(const io::RecordingOptions& options) { return scansOf(io::openRecording(options)); }

std::vector<RangeImage> captureScans(const std::string& pcap, const std::string& json) {
  io::RecordingOptions options;
  options.input = pcap;
  options.metadata = json;
  return scansOf(options);
}

void expectSameImages(const std::vector<RangeImage>& expected, const std::vector<RangeImage>& actual) {
  ASSERT_EQ(expected.size(), actual.size());
  for (std::size_t k = 0; k < expected.size(); ++k) {
    SCOPED_TRACE("scan " + std::to_string(k));
    ASSERT_EQ(expected[k].range.size(), actual[k].range.size());
    std::size_t differing = 0;
    for (std::size_t i = 0; i < expected[k].range.size(); ++i)
      differing += isValidRange(expected[k].range[i]) != isValidRange(actual[k].range[i]) ||
                   (isValidRange(expected[k].range[i]) && expected[k].range[i] != actual[k].range[i]);
    EXPECT_EQ(differing, 0u);
    EXPECT_EQ(expected[k].column_timestamp_ns, actual[k].column_timestamp_ns);
    EXPECT_EQ(expected[k].stamp_ns, actual[k].stamp_ns);
    EXPECT_GT(actual[k].validCount(), 0u);
  }
}

// The staggered millimetre ranges' md5, as SOURCE.md gives the bag's golden value.
std::string rangeMd5(const RangeImage& image) {
  std::vector<uint32_t> millimetres(image.range.size(), 0);
  for (std::size_t i = 0; i < image.range.size(); ++i)
    if (isValidRange(image.range[i])) millimetres[i] = uint32_t(std::lround(image.range[i] * 1000.0f));
  return test::md5Hex(millimetres);
}

TEST(Recording, OusterPacketBagGivesTheGoldenImageAndThePcapPathsImage) {
  RIM_REQUIRE_DATA(bag_path, "ouster-extra/512x10_raw.bag");
  RIM_REQUIRE_DATA(json, "ouster-extra/512x10_raw.bag.metadata.json");
  io::RecordingOptions options;
  options.input = bag_path;
  const io::Recording recording = io::openRecording(options);
  EXPECT_EQ(recording.kind, io::RecordingKind::kOusterPacketBag);
  EXPECT_EQ(recording.topic, "/os_node0/lidar_packets");
  EXPECT_TRUE(contains(recording.description, "/os_node0/metadata")) << recording.description;
  const std::vector<RangeImage> from_bag = scansOf(options);
  ASSERT_EQ(from_bag.size(), 1u);
  EXPECT_EQ(from_bag[0].frame_id, 1798u);
  EXPECT_EQ(from_bag[0].validCount(), 28751u);                         // SOURCE.md
  EXPECT_EQ(rangeMd5(from_bag[0]), "9d68e9c6cde0eab641726111793b2a0e");  // SOURCE.md

  // The same packets in a pcap, read with the metadata file: the same image.
  const fs::path folder = freshFolder("packets");
  const OusterMetadata metadata = loadOusterMetadata(json);
  {
    io::PcapWriter pcap((folder / "capture.pcap").string());
    const io::BagReader bag(bag_path);
    bag.forEachOusterPacket("/os_node0/lidar_packets", [&](const io::BagPacket& packet) {
      io::UdpDatagram datagram;
      datagram.payload = packet.data;
      datagram.size = packet.size;
      datagram.source_port = datagram.destination_port = uint16_t(metadata.udp_port_lidar);
      datagram.timestamp_ns = packet.bag_time_ns;
      pcap.write(datagram);
      return true;
    });
    pcap.close();
  }
  expectSameImages(captureScans((folder / "capture.pcap").string(), json), from_bag);
  // The metadata file instead of the bag's topic: the same image again.
  options.metadata = json;
  expectSameImages(scansOf(options), from_bag);
  // The IMU packets chosen by mistake: named, with both sizes.
  options.topic = "/os_node0/imu_packets";
  const std::string error = errorOf([&] { scansOf(options); });
  EXPECT_TRUE(contains(error, "/os_node0/imu_packets") && contains(error, "48 bytes") && contains(error, "8448"))
      << error;
  fs::remove_all(folder);
}

// A real capture's packets in bags of both driver generations' PacketMsg, with
// the metadata on a latched-style string topic: the capture's scans.
TEST(Recording, BothPacketMessageGenerationsGiveTheCapturesScans) {
  RIM_REQUIRE_DATA(pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(json, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const std::vector<RangeImage> from_pcap = captureScans(pcap, json);
  ASSERT_EQ(from_pcap.size(), 3u);
  const OusterMetadata metadata = loadOusterMetadata(json);
  std::ifstream metadata_file(json);
  std_msgs::String metadata_text;
  metadata_text.data.assign(std::istreambuf_iterator<char>(metadata_file), std::istreambuf_iterator<char>());

  const fs::path folder = freshFolder("generations");
  for (const int generation : {1, 2}) {
    SCOPED_TRACE("generation " + std::to_string(generation));
    const std::string bag_path = (folder / ("packets" + std::to_string(generation) + ".bag")).string();
    {
      rosbag::Bag bag(bag_path, rosbag::bagmode::Write);
      bag.write("/ouster/metadata", ros::Time(1.0), metadata_text);
      io::PcapReader reader(pcap);
      io::UdpDatagram datagram;
      std::size_t written = 0;
      while (reader.next(datagram)) {
        if (datagram.destination_port != metadata.udp_port_lidar) continue;  // IMU packets have their own topic
        const std::vector<uint8_t> bytes(datagram.payload, datagram.payload + datagram.size);
        const ros::Time time(1.0 + 1e-4 * double(++written));
        if (generation == 1)
          bag.write("/ouster/lidar_packets", time, test::PacketMessage<1>{bytes});
        else
          bag.write("/ouster/lidar_packets", time, test::PacketMessage<2>{bytes});
      }
      ASSERT_EQ(written, 192u);  // SOURCE.md: 192 lidar packets
    }
    io::RecordingOptions options;
    options.input = bag_path;
    expectSameImages(from_pcap, scansOf(options));
  }
  fs::remove_all(folder);
}

// KITTI scans as velodyne_pointcloud would publish them (x y z intensity
// float32), stamped like the folder's times.txt.
void writeCloudBag(const std::string& path, const std::vector<std::string>& scans,
                   const std::vector<double>& times_s, const std::vector<std::string>& topics) {
  rosbag::Bag bag(path, rosbag::bagmode::Write);
  for (std::size_t k = 0; k < scans.size(); ++k) {
    const PointCloudInput scan = io::readKittiVelodyne(scans[k]);
    sensor_msgs::PointCloud2 cloud;
    cloud.header.stamp.fromSec(times_s[k]);
    cloud.header.frame_id = "velodyne";
    cloud.header.seq = uint32_t(k);
    cloud.height = 1;
    cloud.width = uint32_t(scan.size());
    const char* names[] = {"x", "y", "z", "intensity"};
    for (uint32_t f = 0; f < 4; ++f) {
      sensor_msgs::PointField field;
      field.name = names[f];
      field.offset = 4 * f;
      field.datatype = sensor_msgs::PointField::FLOAT32;
      field.count = 1;
      cloud.fields.push_back(field);
    }
    cloud.point_step = 16;
    cloud.row_step = 16 * cloud.width;
    cloud.is_dense = true;
    cloud.data.resize(cloud.row_step);
    for (std::size_t i = 0; i < scan.size(); ++i) {
      std::memcpy(&cloud.data[16 * i], scan.points[i].data(), 12);
      std::memcpy(&cloud.data[16 * i + 12], &scan.intensity[i], 4);
    }
    for (const std::string& topic : topics) bag.write(topic, cloud.header.stamp, cloud);
  }
}

struct KittiCopy {
  fs::path folder;  // scans/ (a folder of .bin with times.txt) and clouds.bag
  std::vector<double> times_s;
  std::vector<std::string> files;  // the original scans
};

KittiCopy kittiCopy(const std::string& velodyne, std::size_t scans, const std::vector<std::string>& topics) {
  KittiCopy copy{freshFolder("kitti"), {}, {}};
  std::vector<std::string> files;
  for (const auto& entry : fs::directory_iterator(velodyne)) files.push_back(entry.path().string());
  std::sort(files.begin(), files.end());
  files.resize(std::min(files.size(), scans));
  fs::create_directories(copy.folder / "scans");
  std::ofstream times(copy.folder / "scans" / "times.txt");
  for (std::size_t k = 0; k < files.size(); ++k) {
    fs::copy_file(files[k], copy.folder / "scans" / fs::path(files[k]).filename());
    copy.times_s.push_back(1317384520.0 + 0.125 * double(k));  // exact in binary: the same stamps both ways
    times << std::setprecision(17) << copy.times_s.back() << "\n";
  }
  times.close();
  writeCloudBag((copy.folder / "clouds.bag").string(), files, copy.times_s, topics);
  copy.files = files;
  return copy;
}

TEST(Recording, PointCloudBagGivesTheFoldersImages) {
  RIM_REQUIRE_DATA(velodyne, "kitti-raw-22/velodyne");
  const KittiCopy copy = kittiCopy(velodyne, 3, {"/velodyne_points"});
  io::RecordingOptions bag_options;
  bag_options.input = (copy.folder / "clouds.bag").string();
  const io::Recording bag = io::openRecording(bag_options);
  EXPECT_EQ(bag.kind, io::RecordingKind::kPointCloudBag);
  EXPECT_EQ(bag.topic, "/velodyne_points");
  EXPECT_EQ(bag.frame, "velodyne");
  EXPECT_EQ(bag.expected_frames, 3);
  // No sensor option: a model estimated from the clouds, with its fit.
  ASSERT_TRUE(bag.model_info.fit);
  EXPECT_GT(bag.model_info.fit->keptShare(), 0.9);
  EXPECT_TRUE(contains(bag.model_info.summary, "estimated from the first 3 scans")) << bag.model_info.summary;
  io::RecordingOptions folder_options;
  folder_options.input = (copy.folder / "scans").string();
  const io::Recording folder = io::openRecording(folder_options);
  EXPECT_EQ(folder.kind, io::RecordingKind::kCloudFiles);
  EXPECT_EQ(folder.model->intrinsics().altitude_rad, bag.model->intrinsics().altitude_rad);
  const std::vector<RangeImage> from_bag = scansOf(bag);
  expectSameImages(scansOf(folder), from_bag);
  EXPECT_NEAR(double(from_bag[1].stamp_ns) * 1e-9, copy.times_s[1], 1e-6);
  fs::remove_all(copy.folder);
}

TEST(Recording, BagTopicsAreChosenOrNamed) {
  RIM_REQUIRE_DATA(velodyne, "kitti-raw-22/velodyne");
  const KittiCopy copy = kittiCopy(velodyne, 1, {"/front/points", "/rear/points"});
  io::RecordingOptions options;
  options.input = (copy.folder / "clouds.bag").string();
  const std::string ambiguous = errorOf([&] { io::openRecording(options); });
  EXPECT_TRUE(contains(ambiguous, "--topic") && contains(ambiguous, "/front/points") &&
              contains(ambiguous, "/rear/points"))
      << ambiguous;
  options.topic = "/rear/points";
  EXPECT_EQ(io::openRecording(options).topic, "/rear/points");
  options.topic = "/side/points";
  const std::string unknown = errorOf([&] { io::openRecording(options); });
  EXPECT_TRUE(contains(unknown, "/side/points") && contains(unknown, "/front/points")) << unknown;
  // A bag without any cloud or packet topic says what it holds.
  {
    rosbag::Bag bag((copy.folder / "strings.bag").string(), rosbag::bagmode::Write);
    std_msgs::String text;
    text.data = "hello";
    bag.write("/chatter", ros::Time(1.0), text);
  }
  options.input = (copy.folder / "strings.bag").string();
  options.topic.clear();
  const std::string none = errorOf([&] { io::openRecording(options); });
  EXPECT_TRUE(contains(none, "no PointCloud2 topic") && contains(none, "/chatter")) << none;
  fs::remove_all(copy.folder);
}

TEST(Recording, PcdRoundTripsInAsciiAndBinary) {
  RIM_REQUIRE_DATA(scan_path, "kitti00/velodyne/000094.bin");
  PointCloudInput scan = io::readKittiVelodyne(scan_path);
  scan.ring.resize(scan.size());
  scan.time_offset_s.resize(scan.size());
  for (std::size_t i = 0; i < scan.size(); ++i) {
    scan.ring[i] = uint16_t(i % 64);
    scan.time_offset_s[i] = 1e-6f * float(i);
  }
  scan.points[7] = Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN());  // a no-return point
  const fs::path folder = freshFolder("pcd");
  for (const auto encoding : {io::PcdEncoding::kAscii, io::PcdEncoding::kBinary}) {
    const bool ascii = encoding == io::PcdEncoding::kAscii;
    SCOPED_TRACE(ascii ? "ascii" : "binary");
    const std::string path = (folder / (ascii ? "ascii.pcd" : "binary.pcd")).string();
    io::writePcd(path, scan, encoding);
    PointCloudReadReport report;
    const PointCloudInput read = io::readPcd(path, 5000000000ull, &report);
    ASSERT_EQ(read.size(), scan.size());
    std::size_t differing = 0;
    for (std::size_t i = 0; i < scan.size(); ++i)
      differing += i != 7 && (read.points[i] != scan.points[i] || read.intensity[i] != scan.intensity[i] ||
                              read.ring[i] != scan.ring[i] || read.time_offset_s[i] != scan.time_offset_s[i]);
    EXPECT_EQ(differing, 0u);
    EXPECT_TRUE(std::isnan(read.points[7].x()));
    EXPECT_EQ(report.non_finite, 1u);
    EXPECT_EQ(report.time_field, "time");
    EXPECT_EQ(read.stamp_ns, 5000000000ull);
  }
  fs::remove_all(folder);
}

// binary_compressed as PCL writes it (fields one after the other, LZF); the
// LZF stream here is literal runs and back references made by hand.
TEST(Recording, PcdBinaryCompressedIsUnpacked) {
  const std::vector<float> x = {1, 2, 3, 4}, y = {5, 5, 5, 5}, z = {0.5f, 0.5f, 0.5f, 0.5f};
  std::string fields;
  for (const auto* values : {&x, &y, &z}) fields.append(reinterpret_cast<const char*>(values->data()), 16);
  // x, y and z's first value as literal runs (32 and 4 bytes), z's other three
  // values as one back reference of 12 bytes at distance 4 (overlapping copy).
  std::string lzf;
  lzf += char(32 - 1);
  lzf += fields.substr(0, 32);
  lzf += char(4 - 1);
  lzf += fields.substr(32, 4);
  lzf += char(7 << 5);       // length 7 + the next byte + 2
  lzf += char(12 - 7 - 2);
  lzf += char(4 - 1);        // distance 4
  std::string file = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 4\nHEIGHT 1\n"
                     "POINTS 4\nDATA binary_compressed\n";
  const uint32_t sizes[2] = {uint32_t(lzf.size()), 48};
  file.append(reinterpret_cast<const char*>(sizes), 8);
  file += lzf;
  const fs::path folder = freshFolder("pcd_compressed");
  std::ofstream(folder / "c.pcd", std::ios::binary) << file;
  const PointCloudInput cloud = io::readPcd((folder / "c.pcd").string());
  ASSERT_EQ(cloud.size(), 4u);
  for (std::size_t i = 0; i < 4; ++i) EXPECT_EQ(cloud.points[i], Eigen::Vector3f(x[i], y[i], z[i])) << i;
  fs::remove_all(folder);
}

// A real Ouster capture unprojected into PCD scans with a ring field (as a
// driver's cloud): the model estimated from the rings keeps nearly every
// point, and forEachScan projects through the ring map.
TEST(Recording, PcdFolderWithRingsGetsAModelFromItsRings) {
  RIM_REQUIRE_DATA(pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(json, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  const std::vector<RangeImage> scans = captureScans(pcap, json);
  ASSERT_EQ(scans.size(), 3u);
  const fs::path folder = freshFolder("rings");
  std::ofstream times(folder / "times.txt");
  std::size_t measured = 0;
  for (std::size_t k = 0; k < scans.size(); ++k) {
    PointCloudInput cloud;
    for (int v = 0; v < scans[k].rows(); ++v)
      for (int u = 0; u < scans[k].columns(); ++u)
        if (scans[k].valid(v, u)) {
          cloud.points.push_back(scans[k].model->unproject(u, v, scans[k].at(v, u)));
          cloud.ring.push_back(uint16_t(v));
        }
    cloud.organized_width = int(cloud.size());
    measured += cloud.size();
    io::writePcd((folder / ("scan" + std::to_string(k) + ".pcd")).string(), cloud, io::PcdEncoding::kBinary);
    times << std::setprecision(17) << double(scans[k].stamp_ns) * 1e-9 << "\n";
  }
  times.close();
  io::RecordingOptions options;
  options.input = folder.string();
  const io::Recording recording = io::openRecording(options);
  EXPECT_EQ(recording.kind, io::RecordingKind::kCloudFiles);
  EXPECT_EQ(recording.model->rows(), 128);
  EXPECT_EQ(recording.model_info.ring_to_row.size(), 128u);
  ASSERT_TRUE(recording.model_info.fit);
  EXPECT_GT(recording.model_info.fit->keptShare(), 0.99) << recording.model_info.summary;
  EXPECT_TRUE(recording.model_info.warning.empty()) << recording.model_info.warning;
  io::RecordingStatistics statistics;
  const std::vector<RangeImage> images = scansOf(recording, &statistics);
  ASSERT_EQ(images.size(), 3u);
  EXPECT_EQ(statistics.scans, 3u);
  EXPECT_EQ(statistics.projection.measured(), measured);
  EXPECT_GT(statistics.projection.keptFraction(), 0.99);
  for (std::size_t k = 0; k < 3; ++k) EXPECT_NEAR(double(images[k].stamp_ns), double(scans[k].stamp_ns), 1000.0);
  fs::remove_all(folder);
}

TEST(Recording, MalformedFilesNameTheProblem) {
  const fs::path folder = freshFolder("malformed");
  const auto pcdError = [&](const std::string& text) {
    std::ofstream(folder / "bad.pcd", std::ios::binary) << text;
    return errorOf([&] { io::readPcd((folder / "bad.pcd").string()); });
  };
  const std::string header = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n";
  std::string error = pcdError("VERSION 0.7\nFIELDS x y z\nTYPE F F F\nWIDTH 1\nDATA ascii\n1 2 3\n");
  EXPECT_TRUE(contains(error, "bad.pcd") && contains(error, "SIZE")) << error;
  error = pcdError(header + "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n1 2 3\n4 5\n");
  EXPECT_TRUE(contains(error, "point 1") && contains(error, "'z'")) << error;
  error = pcdError(header + "WIDTH 2\nHEIGHT 1\nPOINTS 3\nDATA ascii\n1 2 3\n4 5 6\n");
  EXPECT_TRUE(contains(error, "POINTS 3")) << error;
  error = pcdError(header + "WIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA binary\n" + std::string(30, '\0'));
  EXPECT_TRUE(contains(error, "30 bytes") && contains(error, "36")) << error;
  error = pcdError("VERSION 0.7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2\n");
  EXPECT_TRUE(contains(error, "'z'") && contains(error, "missing")) << error;
  error = pcdError("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 8\nTYPE F F I\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n");
  EXPECT_TRUE(contains(error, "'z'") && contains(error, "SIZE 8")) << error;
  error = pcdError("not a pcd at all");
  EXPECT_TRUE(contains(error, "line 1") && contains(error, "unknown header line")) << error;
  error = pcdError(header + "WIDTH 1\n");
  EXPECT_TRUE(contains(error, "no DATA line")) << error;

  std::ofstream(folder / "broken.bag") << "#ROSBAG V2.0\nthis is not a bag";
  error = errorOf([&] { io::BagReader bag((folder / "broken.bag").string()); });
  EXPECT_TRUE(contains(error, "broken.bag")) << error;

  // A folder mixing scan formats is refused, naming both.
  fs::create_directories(folder / "mixed");
  std::ofstream(folder / "mixed" / "a.pcd") << "x";
  std::ofstream(folder / "mixed" / "b.ply") << "x";
  io::RecordingOptions options;
  options.input = (folder / "mixed").string();
  error = errorOf([&] { io::openRecording(options); });
  EXPECT_TRUE(contains(error, ".pcd") && contains(error, ".ply")) << error;
  fs::remove_all(folder);
}

// A scan file that cannot be read, in the middle of a real KITTI folder: with
// statistics it is skipped and named, and the scans after it keep their place
// (frame id, stamp) and their images; without, its reader's error goes on.
TEST(Recording, AnUnreadableScanIsSkippedAndNamed) {
  RIM_REQUIRE_DATA(velodyne, "kitti-raw-22/velodyne");
  const KittiCopy copy = kittiCopy(velodyne, 6, {"/velodyne_points"});
  io::RecordingOptions options;
  options.input = (copy.folder / "scans").string();
  options.sensor = "HDL-64E";
  const std::vector<RangeImage> intact = scansOf(options);
  ASSERT_EQ(intact.size(), 6u);
  const fs::path damaged = copy.folder / "scans" / fs::path(copy.files[3]).filename();
  fs::resize_file(damaged, fs::file_size(damaged) - 5);  // not a whole number of points
  const io::Recording recording = io::openRecording(options);
  EXPECT_THROW(scansOf(recording), io::KittiFormatError);
  io::RecordingStatistics statistics;
  const std::vector<RangeImage> images = scansOf(recording, &statistics);
  ASSERT_EQ(images.size(), 5u);
  EXPECT_EQ(statistics.scans, 5u);
  EXPECT_EQ(statistics.unreadable, 1u);
  ASSERT_EQ(statistics.unreadable_examples.size(), 1u);
  EXPECT_TRUE(contains(statistics.unreadable_examples[0], damaged.filename().string()))
      << statistics.unreadable_examples[0];
  const std::vector<std::size_t> places = {0, 1, 2, 4, 5};
  for (std::size_t k = 0; k < images.size(); ++k) {
    EXPECT_EQ(images[k].frame_id, places[k]);
    EXPECT_EQ(images[k].stamp_ns, intact[places[k]].stamp_ns);
    EXPECT_EQ(rangeMd5(images[k]), rangeMd5(intact[places[k]])) << k;
  }
  const std::string warning = io::readingLossWarning(statistics);
  EXPECT_TRUE(contains(warning, "1 scan could not be read") && contains(warning, damaged.filename().string()))
      << warning;
  io::RecordingStatistics whole;
  io::forEachScan(
      io::openRecording(options), [](const RangeImage&) { return true; }, &whole);
  EXPECT_EQ(whole.unreadable, 1u);

  // The model estimated from the first clouds skips it too.
  options.sensor.clear();
  options.estimation_scans = 4;
  const io::Recording estimated = io::openRecording(options);
  EXPECT_TRUE(contains(estimated.model_info.summary, "estimated from the first 4 scans"))
      << estimated.model_info.summary;

  // None readable: the first one's error, with or without statistics.
  for (const std::string& file : copy.files) {
    const fs::path scan = copy.folder / "scans" / fs::path(file).filename();
    fs::resize_file(scan, fs::file_size(scan) - 3);
  }
  const std::string none = errorOf([&] { io::openRecording(options); });
  EXPECT_TRUE(contains(none, fs::path(copy.files[0]).filename().string()) && contains(none, "multiple of 16"))
      << none;
  fs::remove_all(copy.folder);
}

// A capture cut off mid-record (a real Ouster pcap, truncated): the scans
// before the cut are given and the early end is said; the intact capture
// reads without a loss to report, also when --frames stops it early.
TEST(Recording, ACaptureCutOffGivesItsScansAndSaysSo) {
  RIM_REQUIRE_DATA(pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(json, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  io::RecordingOptions options;
  options.input = pcap;
  options.metadata = json;
  io::RecordingStatistics intact;
  const std::size_t all = io::forEachScan(
      io::openRecording(options), [](const RangeImage&) { return true; }, &intact);
  ASSERT_GE(all, 3u);
  EXPECT_EQ(io::readingLossWarning(intact), "");
  ASSERT_TRUE(intact.pcap && intact.packets);
  EXPECT_EQ(intact.packets->scans, all);

  io::RecordingOptions first = options;
  first.frames = 1;
  io::RecordingStatistics limited;
  EXPECT_EQ(io::forEachScan(
                io::openRecording(first), [](const RangeImage&) { return true; }, &limited),
            1u);
  EXPECT_EQ(io::readingLossWarning(limited), "");
  ASSERT_TRUE(limited.packets);
  EXPECT_LT(limited.packets->packets, intact.packets->packets);  // it stopped reading at the first scan

  const fs::path folder = freshFolder("cut");
  const fs::path cut = folder / "cut.pcap";
  fs::copy_file(pcap, cut);
  fs::resize_file(cut, fs::file_size(cut) * 3 / 4);
  options.input = cut.string();
  io::RecordingStatistics statistics;
  const std::size_t given = io::forEachScan(
      io::openRecording(options), [](const RangeImage&) { return true; }, &statistics);
  EXPECT_GT(given, 0u);
  EXPECT_LE(given, all);
  EXPECT_FALSE(statistics.stopped_early.empty());
  ASSERT_TRUE(statistics.packets);
  EXPECT_LT(statistics.packets->packets, intact.packets->packets);
  const std::string warning = io::readingLossWarning(statistics);
  EXPECT_TRUE(contains(warning, "stopped early, after " + std::to_string(given) + " scans")) << warning;
  fs::remove_all(folder);
}

// rim itself: the bag of plain PointCloud2 and the folder of the same scans
// give the same trajectory, with the estimated model logged once; rim decode
// reads a folder of PCD scans.
using RecordingCommand = test::RimCommandTest;

TEST_F(RecordingCommand, BagAndFolderOfTheSameScansGiveTheSameTrajectory) {
  RIM_REQUIRE_DATA(velodyne, "kitti-raw-22/velodyne");
  const KittiCopy copy = kittiCopy(velodyne, 4, {"/velodyne_points"});
  const test::RunResult bag = rim("odometry " + (copy.folder / "clouds.bag").string() + " --out " + path("bag.txt"));
  ASSERT_EQ(bag.exit_code, 0) << bag.err;
  const test::RunResult folder =
      rim("odometry " + (copy.folder / "scans").string() + " --out " + path("folder.txt"));
  ASSERT_EQ(folder.exit_code, 0) << folder.err;
  EXPECT_TRUE(contains(bag.err, "sensor model estimated from the first 4 scans")) << bag.err;
  const auto from_bag = io::readKittiPosesWithTimes(path("bag.txt"));
  const auto from_folder = io::readKittiPosesWithTimes(path("folder.txt"));
  ASSERT_EQ(from_bag.size(), 4u);
  ASSERT_EQ(from_folder.size(), 4u);
  for (std::size_t k = 0; k < 4; ++k) {
    EXPECT_NEAR(from_bag[k].time_s, copy.times_s[k], 1e-6);
    EXPECT_NEAR(from_bag[k].time_s, from_folder[k].time_s, 1e-6);
    EXPECT_TRUE(from_bag[k].pose.isApprox(from_folder[k].pose, 1e-9)) << k;
  }
  // The car moves forward about 0.8 m a scan (SOURCE.md: 16.8 m in 21 steps).
  EXPECT_GT(from_bag.back().pose.translation().norm(), 1.5);

  fs::create_directories(path("pcd"));
  for (std::size_t k = 0; k < 2; ++k) {
    const PointCloudInput scan = io::readKittiVelodyne(copy.files[k]);
    io::writePcd(path("pcd/" + std::to_string(k) + ".pcd"), scan, io::PcdEncoding::kBinary);
  }
  const test::RunResult decode = rim("decode " + path("pcd") + " --out " + path("decoded"));
  ASSERT_EQ(decode.exit_code, 0) << decode.err << decode.out;
  EXPECT_TRUE(fs::exists(path("decoded/scan_000001.ply")));
  EXPECT_TRUE(contains(decode.out, "2 scans written")) << decode.out;
  fs::remove_all(copy.folder);
}

// rim odometry and rim map over a folder with a damaged scan: the others are
// processed and written, the damaged one is named in a warning and in the
// JSON, and rim map still matches scans to poses by their place.
TEST_F(RecordingCommand, ADamagedScanIsNamedAndTheRestWritten) {
  RIM_REQUIRE_DATA(velodyne, "kitti-raw-22/velodyne");
  const KittiCopy copy = kittiCopy(velodyne, 6, {"/velodyne_points"});
  const std::string scans = (copy.folder / "scans").string();
  const test::RunResult intact = rim("odometry " + scans + " --sensor HDL-64E --out " + path("intact.txt"));
  ASSERT_EQ(intact.exit_code, 0) << intact.err;
  EXPECT_FALSE(contains(intact.err, "could not be read")) << intact.err;
  const fs::path damaged = copy.folder / "scans" / fs::path(copy.files[2]).filename();
  fs::resize_file(damaged, fs::file_size(damaged) - 7);
  const test::RunResult odometry = rim("odometry " + scans + " --sensor HDL-64E --out " + path("traj.txt"));
  ASSERT_EQ(odometry.exit_code, 0) << odometry.err;
  EXPECT_TRUE(contains(odometry.err, "warning: 1 scan could not be read") &&
              contains(odometry.err, damaged.filename().string()))
      << odometry.err;
  const auto poses = io::readKittiPosesWithTimes(path("traj.txt"));
  ASSERT_EQ(poses.size(), 5u);
  EXPECT_NEAR(poses[2].time_s, copy.times_s[3], 1e-6);  // the scan after the damaged one keeps its time
  const std::string summary = test::readText(path("traj_summary.json"));
  EXPECT_TRUE(contains(summary, "\"unreadable\" : 1")) << summary;

  const test::RunResult map = rim("map " + scans + " --sensor HDL-64E --poses " + path("intact.txt") + " --out " +
                                  path("mesh.ply") + " --json " + path("map.json"));
  ASSERT_EQ(map.exit_code, 0) << map.err;
  EXPECT_TRUE(contains(map.out, "5 scans (5 integrated")) << map.out;
  EXPECT_TRUE(contains(map.err, damaged.filename().string())) << map.err;
  EXPECT_TRUE(contains(test::readText(path("map.json")), "\"unreadable\" : 1"));
  fs::remove_all(copy.folder);
}

}  // namespace
}  // namespace range_image_mapping
