// rim decode: an Ouster pcap + metadata into one PLY cloud (lidar frame, with
// the pixel each point came from) and one range-image PNG per complete scan.
#include "commands.h"

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
  std::string capture;
  std::string metadata;
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

int runDecode(const DecodeOptions& options) {
  const OusterMetadata metadata = loadOusterMetadata(options.metadata);
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
      io::readOusterScans(options.capture, metadata, [&](const LidarScan& scan) {
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
        writeScanPly(stem + ".ply", image);
        io::RangePngOptions png;
        png.row_repeat = row_repeat;
        io::writeRangeImagePng(stem + "_range.png", image, png);
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
      "decode", "Decode an Ouster pcap: one PLY cloud (lidar frame, per-point row/col/range) and one "
                "destaggered range-image PNG per complete scan");
  command.option("capture", options->capture, "Ouster capture (.pcap)").required().check(existingFile());
  command.option("--metadata,-m", options->metadata, "sensor metadata JSON (flat or nested)")
      .required()
      .check(existingFile());
  command.option("--out,-o", options->output_directory, "output directory").required();
  command.option("--return", options->return_name, "which return of a dual-return profile")
      .check(oneOf({"first", "second"}));
  command.flag("--include-incomplete", options->include_incomplete,
               "also write scans with missing columns (they stay invalid)");
  command.option("--png-row-repeat", options->row_repeat,
                 "repeat each PNG row this many times (default: 256 / beams)");
  command.callback([options] {
    const int status = runDecode(*options);
    if (status != 0) throw CommandFailed("no complete scan in " + options->capture, status);
  });
}

}  // namespace range_image_mapping::tool
