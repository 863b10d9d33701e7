#include "range_image_mapping/ouster_packet.h"

#include "little_endian.h"

#include <boost/crc.hpp>

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>

namespace range_image_mapping {
namespace {

constexpr std::size_t kPacketHeaderSize = 32;  // non-LEGACY profiles
constexpr std::size_t kPacketFooterSize = 32;
constexpr std::size_t kLegacyColumnHeaderSize = 16;  // timestamp, measurement id, frame id, encoder
constexpr std::size_t kLegacyColumnFooterSize = 4;   // status
constexpr std::size_t kColumnHeaderSize = 12;        // timestamp, measurement id, status
constexpr std::size_t kMeasurementIdOffset = 8;      // in the column header, every profile
constexpr std::size_t kLegacyFrameIdOffset = 10;     // in the LEGACY column header
constexpr std::size_t kLegacyEncoderOffset = 12;     // in the LEGACY column header
constexpr std::size_t kColumnStatusOffset = 10;      // in the non-LEGACY column header
constexpr std::size_t kFrameIdOffset = 2;            // in the packet header
constexpr uint16_t kLidarPacketType = 1;
constexpr uint32_t kLegacyValidColumn = 0xFFFFFFFFu;
constexpr std::size_t kChecksumSize = 8;  // the footer's last bytes (firmware 3.x)
// CRC-64/XZ: the ECMA-182 polynomial, reflected in and out, all-ones initial value and final XOR.
using Crc64 = boost::crc_optimal<64, 0x42F0E1EBA9EA3693ull, ~0ull, ~0ull, true, true>;

// Raw pointers into the scan's fields, fetched once per packet.
struct ScanFields {
  uint32_t* range;
  uint32_t* range2;
  uint8_t* reflectivity;
  uint8_t* reflectivity2;
  uint16_t* signal;
  uint16_t* signal2;
  uint16_t* near_ir;
};

// One struct per pixel layout, so the profile is chosen once per packet and the
// per-pixel loop has no branch on it.
// LEGACY and RNG19_RFL8_SIG16_NIR16 share a 12-byte pixel and differ in the
// width of the range field (20 and 19 bits) and in the packet header.
template <bool Legacy, uint32_t RangeMask>
struct TwelveBytePixel {
  static constexpr bool kLegacy = Legacy;
  static constexpr std::size_t kBytes = 12;
  static void decode(const uint8_t* pixel, const ScanFields& fields, std::size_t i) {
    fields.range[i] = readLittleEndian<uint32_t>(pixel) & RangeMask;
    fields.reflectivity[i] = pixel[4];
    fields.signal[i] = readLittleEndian<uint16_t>(pixel + 6);
    fields.near_ir[i] = readLittleEndian<uint16_t>(pixel + 8);
  }
};
using LegacyPixel = TwelveBytePixel<true, 0xFFFFFu>;
using Rng19Rfl8Sig16Nir16Pixel = TwelveBytePixel<false, 0x7FFFFu>;

struct Rng19Rfl8Sig16Nir16DualPixel {
  static constexpr bool kLegacy = false;
  static constexpr std::size_t kBytes = 16;
  static void decode(const uint8_t* pixel, const ScanFields& fields, std::size_t i) {
    fields.range[i] = readLittleEndian<uint32_t>(pixel) & 0x7FFFFu;
    fields.reflectivity[i] = pixel[3];
    fields.range2[i] = readLittleEndian<uint32_t>(pixel + 4) & 0x7FFFFu;
    fields.reflectivity2[i] = pixel[7];
    fields.signal[i] = readLittleEndian<uint16_t>(pixel + 8);
    fields.signal2[i] = readLittleEndian<uint16_t>(pixel + 10);
    fields.near_ir[i] = readLittleEndian<uint16_t>(pixel + 12);
  }
};

struct Rng15Rfl8Nir8Pixel {
  static constexpr bool kLegacy = false;
  static constexpr std::size_t kBytes = 4;
  static void decode(const uint8_t* pixel, const ScanFields& fields, std::size_t i) {
    const uint32_t word = readLittleEndian<uint32_t>(pixel);
    fields.range[i] = (word & 0x7FFFu) << 3;  // 8 mm steps
    fields.reflectivity[i] = static_cast<uint8_t>(word >> 16);
    fields.near_ir[i] = static_cast<uint16_t>((word >> 24) << 4);
  }
};


}  // namespace

std::size_t pixelBytes(UdpProfile profile) {
  switch (profile) {
    case UdpProfile::kLegacy: return LegacyPixel::kBytes;
    case UdpProfile::kRng19Rfl8Sig16Nir16: return Rng19Rfl8Sig16Nir16Pixel::kBytes;
    case UdpProfile::kRng19Rfl8Sig16Nir16Dual: return Rng19Rfl8Sig16Nir16DualPixel::kBytes;
    case UdpProfile::kRng15Rfl8Nir8: return Rng15Rfl8Nir8Pixel::kBytes;
  }
  throw std::invalid_argument("unknown UDP profile");
}

bool hasSignal(UdpProfile profile) { return profile != UdpProfile::kRng15Rfl8Nir8; }
bool hasSecondReturn(UdpProfile profile) { return profile == UdpProfile::kRng19Rfl8Sig16Nir16Dual; }

LidarScan::LidarScan(int scan_rows, int scan_columns, UdpProfile profile)
    : rows(scan_rows), columns(scan_columns) {
  if (rows <= 0 || columns <= 0)
    throw std::invalid_argument("LidarScan: size " + std::to_string(rows) + "x" +
                                std::to_string(columns) + " must be positive");
  const std::size_t pixels = static_cast<std::size_t>(rows) * columns;
  range.assign(pixels, 0);
  reflectivity.assign(pixels, 0);
  near_ir.assign(pixels, 0);
  if (hasSignal(profile)) signal.assign(pixels, 0);
  if (hasSecondReturn(profile)) {
    range2.assign(pixels, 0);
    reflectivity2.assign(pixels, 0);
    signal2.assign(pixels, 0);
  }
  timestamp_ns.assign(columns, 0);
  measurement_id.assign(columns, 0);
  status.assign(columns, 0);
  encoder_count.assign(columns, 0);
}

std::size_t LidarScan::receivedColumns() const {
  return static_cast<std::size_t>(std::count_if(status.begin(), status.end(),
                                                [](uint32_t s) { return s != 0; }));
}

void LidarScan::reset() {
  const auto zero = [](auto& field) { std::fill(field.begin(), field.end(), 0); };
  zero(range);
  zero(range2);
  zero(reflectivity);
  zero(reflectivity2);
  zero(signal);
  zero(signal2);
  zero(near_ir);
  zero(timestamp_ns);
  zero(measurement_id);
  zero(status);
  zero(encoder_count);
  frame_id = 0;
}

PacketFormat::PacketFormat(const OusterMetadata& metadata)
    : profile_(metadata.profile),
      rows_(metadata.pixels_per_column),
      columns_(metadata.columns_per_frame),
      columns_per_packet_(metadata.columns_per_packet) {
  constexpr int kMaxRows = kMaxPixelsPerColumn;
  constexpr int kMaxColumns = 1 << 16;  // measurement ids are 16-bit
  if (rows_ <= 0 || rows_ > kMaxRows || columns_ <= 0 || columns_ > kMaxColumns ||
      columns_per_packet_ <= 0 || columns_per_packet_ > columns_)
    throw std::invalid_argument(
        "PacketFormat: pixels_per_column " + std::to_string(rows_) + " must be within [1, " +
        std::to_string(kMaxRows) + "], columns_per_frame " + std::to_string(columns_) +
        " within [1, " + std::to_string(kMaxColumns) + "], columns_per_packet " +
        std::to_string(columns_per_packet_) + " within [1, columns_per_frame]");
  const std::size_t pixels_size = static_cast<std::size_t>(rows_) * pixelBytes(profile_);
  if (profile_ == UdpProfile::kLegacy) {
    header_size_ = 0;
    column_size_ = kLegacyColumnHeaderSize + pixels_size + kLegacyColumnFooterSize;
    packet_size_ = columns_per_packet_ * column_size_;
  } else {
    header_size_ = kPacketHeaderSize;
    column_size_ = kColumnHeaderSize + pixels_size;
    packet_size_ = kPacketHeaderSize + columns_per_packet_ * column_size_ + kPacketFooterSize;
  }
  // Hand-made metadata may not come from the parser: size the window the same
  // way the intrinsics do, or take the full circle if the intrinsics are unset.
  LidarIntrinsics window_geometry = metadata.intrinsics;
  window_geometry.columns = columns_;
  const auto& window = window_geometry.column_window;
  if (window[0] < 0 || window[0] >= columns_ || window[1] >= columns_)
    window_geometry.column_window = {0, columns_ - 1};
  in_window_.resize(columns_);
  for (int column = 0; column < columns_; ++column)
    in_window_[column] = window_geometry.columnInWindow(column) ? 1 : 0;
  column_window_width_ = window_geometry.columnWindowWidth();
}

uint16_t PacketFormat::measurementId(const uint8_t* packet, int column_in_packet) const {
  return readLittleEndian<uint16_t>(packet + header_size_ + column_in_packet * column_size_ +
                                    kMeasurementIdOffset);
}

uint32_t PacketFormat::frameId(const uint8_t* packet) const {
  return readLittleEndian<uint16_t>(packet + (profile_ == UdpProfile::kLegacy
                                                  ? kLegacyFrameIdOffset
                                                  : kFrameIdOffset));
}

bool PacketFormat::checksumMatches(const uint8_t* packet) const {
  if (profile_ == UdpProfile::kLegacy) return false;
  Crc64 crc;
  crc.process_bytes(packet, packet_size_ - kChecksumSize);
  return crc.checksum() == readLittleEndian<uint64_t>(packet + packet_size_ - kChecksumSize);
}

PacketFormat::Result PacketFormat::validate(const uint8_t* packet, std::size_t size) const {
  if (packet == nullptr || size != packet_size_) return Result::kWrongSize;
  const bool legacy = profile_ == UdpProfile::kLegacy;
  if (!legacy && readLittleEndian<uint16_t>(packet) != kLidarPacketType) return Result::kNotLidar;
  const uint32_t frame_id = frameId(packet);
  for (int c = 0; c < columns_per_packet_; ++c) {
    if (measurementId(packet, c) >= columns_) return Result::kBadColumn;
    if (legacy && readLittleEndian<uint16_t>(packet + c * column_size_ + kLegacyFrameIdOffset) !=
                      frame_id)
      return Result::kBadColumn;
  }
  return Result::kOk;
}

template <typename PixelLayout>
int PacketFormat::decodeColumns(const uint8_t* packet, LidarScan& scan) const {
  constexpr std::size_t kPixelsOffset =
      PixelLayout::kLegacy ? kLegacyColumnHeaderSize : kColumnHeaderSize;
  const ScanFields fields{scan.range.data(),        scan.range2.data(), scan.reflectivity.data(),
                          scan.reflectivity2.data(), scan.signal.data(), scan.signal2.data(),
                          scan.near_ir.data()};
  int new_window_columns = 0;
  // Column headers first, then the pixels row by row: consecutive columns of a
  // row are neighbours in the scan, so each row's writes share cache lines.
  constexpr int kChunk = 64;
  const uint8_t* valid_pixels[kChunk];
  uint16_t valid_columns[kChunk];
  for (int chunk = 0; chunk < columns_per_packet_; chunk += kChunk) {
    int valid = 0;
    for (int c = chunk; c < std::min(chunk + kChunk, columns_per_packet_); ++c) {
      const uint8_t* column = packet + header_size_ + c * column_size_;
      const uint16_t measurement_id = measurementId(packet, c);
      uint32_t status;
      if constexpr (PixelLayout::kLegacy) {
        status = readLittleEndian<uint32_t>(column + kPixelsOffset + rows_ * PixelLayout::kBytes);
        if (status != kLegacyValidColumn) continue;
        scan.encoder_count[measurement_id] =
            readLittleEndian<uint32_t>(column + kLegacyEncoderOffset);
      } else {
        status = readLittleEndian<uint16_t>(column + kColumnStatusOffset);
        if ((status & 1u) == 0) continue;  // bit 0: column valid
      }
      if (scan.status[measurement_id] == 0 && in_window_[measurement_id]) ++new_window_columns;
      scan.status[measurement_id] = status;
      scan.timestamp_ns[measurement_id] = readLittleEndian<uint64_t>(column);
      scan.measurement_id[measurement_id] = measurement_id;
      valid_pixels[valid] = column + kPixelsOffset;
      valid_columns[valid] = measurement_id;
      ++valid;
    }
    for (int row = 0; row < rows_; ++row) {
      const std::size_t row_start = static_cast<std::size_t>(row) * columns_;
      const std::size_t pixel_offset = static_cast<std::size_t>(row) * PixelLayout::kBytes;
      for (int c = 0; c < valid; ++c)
        PixelLayout::decode(valid_pixels[c] + pixel_offset, fields, row_start + valid_columns[c]);
    }
  }
  return new_window_columns;
}

PacketFormat::Result PacketFormat::decode(const uint8_t* packet, std::size_t size, LidarScan& scan,
                                          int* new_window_columns) const {
  if (new_window_columns != nullptr) *new_window_columns = 0;
  const Result result = validate(packet, size);
  if (result != Result::kOk) return result;
  const std::size_t pixels = static_cast<std::size_t>(rows_) * columns_;
  if (scan.rows != rows_ || scan.columns != columns_ || scan.range.size() != pixels ||
      (hasSignal(profile_) && scan.signal.size() != pixels) ||
      (hasSecondReturn(profile_) && scan.range2.size() != pixels))
    throw std::invalid_argument("PacketFormat::decode: scan was not made for this packet format");
  int added = 0;
  switch (profile_) {
    case UdpProfile::kLegacy: added = decodeColumns<LegacyPixel>(packet, scan); break;
    case UdpProfile::kRng19Rfl8Sig16Nir16:
      added = decodeColumns<Rng19Rfl8Sig16Nir16Pixel>(packet, scan);
      break;
    case UdpProfile::kRng19Rfl8Sig16Nir16Dual:
      added = decodeColumns<Rng19Rfl8Sig16Nir16DualPixel>(packet, scan);
      break;
    case UdpProfile::kRng15Rfl8Nir8: added = decodeColumns<Rng15Rfl8Nir8Pixel>(packet, scan); break;
  }
  if (new_window_columns != nullptr) *new_window_columns = added;
  return Result::kOk;
}

void toRangeImage(const LidarScan& scan, const LidarModelConstPtr& model, ReturnIndex which,
                  RangeImage& image) {
  if (!model) throw std::invalid_argument("toRangeImage: no sensor model");
  if (model->rows() != scan.rows || model->columns() != scan.columns)
    throw std::invalid_argument("toRangeImage: scan is " + std::to_string(scan.rows) + "x" +
                                std::to_string(scan.columns) + ", sensor model is " +
                                std::to_string(model->rows()) + "x" +
                                std::to_string(model->columns()));
  const bool first = which == ReturnIndex::kFirst;
  const std::vector<uint32_t>& ranges = first ? scan.range : scan.range2;
  const std::vector<uint8_t>& reflectivity = first ? scan.reflectivity : scan.reflectivity2;
  const std::size_t pixels = static_cast<std::size_t>(scan.rows) * scan.columns;
  if (ranges.size() != pixels || reflectivity.size() != pixels ||
      scan.status.size() != static_cast<std::size_t>(scan.columns) ||
      scan.timestamp_ns.size() != scan.status.size())
    throw std::invalid_argument(first ? "toRangeImage: scan fields do not match its size"
                                      : "toRangeImage: scan has no second return (profile is not "
                                        "RNG19_RFL8_SIG16_NIR16_DUAL)");

  // Every field below is overwritten, so an image of the same model keeps its buffers.
  if (image.model != model || image.range.size() != pixels ||
      image.column_timestamp_ns.size() != static_cast<std::size_t>(scan.columns))
    image = RangeImage(model);
  image.frame_id = scan.frame_id;
  image.column_order = ColumnOrder::kStaggered;
  image.intensity_field = "reflectivity";
  image.intensity.resize(pixels);
  constexpr float kNoReturn = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t i = 0; i < pixels; ++i) {
    const uint32_t millimetres = ranges[i];
    image.range[i] = millimetres == 0 ? kNoReturn : static_cast<float>(millimetres * 0.001);
    image.intensity[i] = reflectivity[i];
  }
  image.stamp_ns = 0;
  for (int u = 0; u < scan.columns; ++u)
    image.column_timestamp_ns[u] = scan.status[u] != 0 ? scan.timestamp_ns[u] : 0;
  // A frame starts at measurement id 0 (even when the column window wraps past
  // W-1), so the lowest valid column is the earliest.
  for (int u = 0; u < scan.columns; ++u) {
    if (scan.status[u] != 0) {
      image.stamp_ns = scan.timestamp_ns[u];
      break;
    }
  }
}

RangeImage toRangeImage(const LidarScan& scan, const LidarModelConstPtr& model, ReturnIndex which) {
  RangeImage image;
  toRangeImage(scan, model, which, image);
  return image;
}

}  // namespace range_image_mapping
