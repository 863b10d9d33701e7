// rim decode: a recording into one PLY cloud (lidar frame, with the pixel each
// point came from) and one range-image PNG per scan. An Ouster pcap keeps its
// packet-level report (incomplete scans, dual returns, packet counts); every
// other recording goes through io/recording with its sensor model.
#include "commands.h"
#include "outputs.h"

#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/io/ply.h"
#include "range_image_mapping/io/png.h"
#include "range_image_mapping/ouster_packet.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <limits>

namespace range_image_mapping::tool {
namespace {

struct DecodeOptions {
  io::RecordingOptions recording;
  std::string output_directory;
  std::string return_name = "first";
  bool include_incomplete = false;
  int row_repeat = 0;  // 0: chosen from the beam count
};

void writeScanPly(const std::string& path, const RangeImage& image) {
  std::vector<Eigen::Vector3f> points;
  std::vector<uint16_t> rows, columns;
  std::vector<float> ranges, intensities;
  const std::size_t count = image.validCount();
  points.reserve(count);
  for (int v = 0; v < image.rows(); ++v)
    for (int u = 0; u < image.columns(); ++u) {
      if (!image.valid(v, u)) continue;
      points.push_back(image.model->unproject(u, v, image.at(v, u)));
      rows.push_back(static_cast<uint16_t>(v));
      columns.push_back(static_cast<uint16_t>(u));  // staggered: the measurement id
      ranges.push_back(image.at(v, u));
      if (!image.intensity.empty()) intensities.push_back(image.intensity[image.index(v, u)]);
    }
  std::vector<io::PlyProperty> properties{{"row", rows}, {"col", columns}, {"range", ranges}};
  if (!intensities.empty()) properties.push_back({image.intensity_field, intensities});
  io::writePlyPointCloud(path, points, properties);
}

void writeScanFiles(const std::string& stem, const RangeImage& image, int row_repeat) {
  writeScanPly(stem + ".ply", image);
  io::RangePngOptions png;
  png.row_repeat = row_repeat;
  io::writeRangeImagePng(stem + "_range.png", image, png);
}

// Any recording other than an Ouster pcap: its scans as the recording gives them.
int runDecodeRecording(const DecodeOptions& options) {
  if (options.return_name == "second")
    throw std::invalid_argument("--return second needs an Ouster pcap of the dual-return profile");
  const io::Recording recording = io::openRecording(options.recording);
  std::cout << "decoding " << recording.description << "\n";
  reportSensorModel(recording);
  std::filesystem::create_directories(options.output_directory);
  const int row_repeat = options.row_repeat > 0 ? options.row_repeat : std::max(1, 256 / recording.model->rows());
  io::RecordingStatistics statistics;
  int written = 0;
  io::forEachScan(
      recording,
      [&](const RangeImage& image) {
        char name[32];
        std::snprintf(name, sizeof name, "scan_%06d", written);
        const std::string stem = options.output_directory + "/" + name;
        writeScanFiles(stem, image, row_repeat);
        std::printf("%8d %9zu valid px  %s.ply, %s_range.png\n", written, image.validCount(), stem.c_str(),
                    stem.c_str());
        ++written;
        return true;
      },
      &statistics);
  reportReading(statistics);
  const ProjectionStatistics& projection = statistics.projection;
  if (projection.input_points > 0)
    std::printf("%d scans written to %s; of %zu measured points %.1f %% kept, %.1f %% outside the model's field of "
                "view, %.1f %% lost to a nearer point in the same pixel; %zu no-return points (NaN or at the "
                "origin)\n",
                written, options.output_directory.c_str(), projection.measured(),
                100.0 * projection.keptFraction(),
                projection.measured() ? 100.0 * projection.outside_model / projection.measured() : 0.0,
                projection.measured() ? 100.0 * projection.occluded / projection.measured() : 0.0,
                projection.non_finite + projection.no_return);
  else
    std::printf("%d scans written to %s\n", written, options.output_directory.c_str());
  return written > 0 ? 0 : 3;
}

bool isOusterPcap(const io::RecordingOptions& recording) {
  const std::filesystem::path input(recording.input);
  return !recording.kitti && std::filesystem::is_regular_file(input) && input.extension() == ".pcap";
}

int runDecode(const DecodeOptions& options) {
  if (!isOusterPcap(options.recording)) return runDecodeRecording(options);
  if (options.recording.metadata.empty())
    throw std::invalid_argument("the pcap " + options.recording.input + " needs its Ouster metadata JSON (--metadata)");
  const OusterMetadata metadata = loadOusterMetadata(options.recording.metadata);
  const bool second_return = options.return_name == "second";
  if (second_return && metadata.profile != UdpProfile::kRng19Rfl8Sig16Nir16Dual)
    throw std::invalid_argument("--return second needs the dual-return profile; this capture is " +
                                std::string(toString(metadata.profile)));
  const auto model = std::make_shared<const LidarModel>(metadata.intrinsics);
  std::filesystem::create_directories(options.output_directory);
  const int window = metadata.intrinsics.columnWindowWidth();
  const int row_repeat = options.row_repeat > 0 ? options.row_repeat : std::max(1, 256 / model->rows());

  std::cout << "sensor " << metadata.prod_line << " firmware " << metadata.firmware << ", "
            << model->rows() << " x " << model->columns() << ", " << toString(metadata.profile)
            << ", column window " << metadata.intrinsics.column_window[0] << ".."
            << metadata.intrinsics.column_window[1] << "\n";
  std::printf("%8s %9s %9s %10s %9s %9s  %s\n", "frame", "columns", "valid px", "span ms", "min m",
              "max m", "files");
  int written = 0, skipped = 0;
  const io::OusterPcapStatistics statistics =
      io::readOusterScans(options.recording.input, metadata, [&](const LidarScan& scan) {
        const int received = static_cast<int>(scan.receivedColumns());
        if (received < window && !options.include_incomplete) {
          std::printf("%8u %4d/%-4d %s\n", scan.frame_id, received, window,
                      "incomplete, skipped (--include-incomplete keeps it)");
          ++skipped;
          return;
        }
        const RangeImage image =
            toRangeImage(scan, model, second_return ? ReturnIndex::kSecond : ReturnIndex::kFirst);
        float nearest = std::numeric_limits<float>::infinity(), farthest = 0.0f;
        for (const float r : image.range)
          if (isValidRange(r)) nearest = std::min(nearest, r), farthest = std::max(farthest, r);
        uint64_t first_time = 0, last_time = 0;
        for (const uint64_t t : image.column_timestamp_ns)
          if (t) first_time = first_time ? std::min(first_time, t) : t, last_time = std::max(last_time, t);
        const std::string stem = options.output_directory + "/scan_" + std::to_string(scan.frame_id);
        writeScanFiles(stem, image, row_repeat);
        std::printf("%8u %4d/%-4d %9zu %10.2f %9.3f %9.3f  %s.ply, %s_range.png\n", scan.frame_id,
                    received, window, image.validCount(), (last_time - first_time) * 1e-6,
                    image.validCount() ? nearest : 0.0f, farthest, stem.c_str(), stem.c_str());
        ++written;
      });
  const BatcherStatistics& batcher = statistics.batcher;
  std::cout << written << " scans written to " << options.output_directory << ", " << skipped
            << " incomplete skipped; " << statistics.lidar_datagrams << " lidar packets, "
            << batcher.wrong_size << " of wrong size, " << batcher.malformed << " malformed, "
            << batcher.bad_checksum << " with a bad checksum, "
            << batcher.stale << " stale, " << batcher.missing_columns << " columns missing"
            << (statistics.classified_by_size ? " (lidar packets recognised by size: no datagram "
                                                "went to the metadata's lidar port)"
                                              : "")
            << "\n";
  if (written == 0 && batcher.wrong_size > 0)
    std::cout << "hint: the metadata expects " << PacketFormat(metadata).packetSize()
              << "-byte lidar packets; does it belong to this capture?\n";
  if (!statistics.pcap.stopped_early.empty())
    std::cout << "warning: the capture ends in a damaged record: " << statistics.pcap.stopped_early << "\n";
  return written > 0 ? 0 : 3;
}

}  // namespace

void addDecodeCommand(Command& rim) {
  auto options = std::make_shared<DecodeOptions>();
  Command& command = rim.subcommand(
      "decode", "Decode a recording (Ouster pcap or packet bag, PointCloud2 bag, .bin/.pcd/.ply scans, KITTI): one "
                "PLY cloud (lidar frame, per-point row/col/range) and one destaggered range-image PNG per scan");
  addRecordingOptions(command, options->recording, kRecordingInputHelp, "decode only the first N scans");
  command.option("--out,-o", options->output_directory, "output directory").required();
  command.option("--return", options->return_name, "which return of a dual-return profile")
      .check(oneOf({"first", "second"}));
  command.flag("--include-incomplete", options->include_incomplete,
               "also write scans with missing columns (they stay invalid)");
  command.option("--png-row-repeat", options->row_repeat,
                 "repeat each PNG row this many times (default: 256 / beams)");
  command.callback([options] {
    const int status = runDecode(*options);
    if (status != 0) throw CommandFailed("no complete scan in " + options->recording.input, status);
  });
}

}  // namespace range_image_mapping::tool
