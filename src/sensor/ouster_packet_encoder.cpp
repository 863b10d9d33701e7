#include "range_image_mapping/ouster_packet_encoder.h"

#include <algorithm>
#include <array>
#include <cstring>
#include <string>

namespace range_image_mapping {
namespace {

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "packets are little-endian, and so must the host be");

template <typename T>
void writeLittleEndian(uint8_t* bytes, T value) {
  std::memcpy(bytes, &value, sizeof(T));
}

// Offsets of ouster-pcaps/SOURCE.md.
constexpr std::size_t kPacketHeaderSize = 32;  // non-LEGACY profiles
constexpr std::size_t kPacketFooterSize = 32;
constexpr std::size_t kLegacyColumnHeaderSize = 16;  // timestamp, measurement id, frame id, encoder
constexpr std::size_t kColumnHeaderSize = 12;        // timestamp, measurement id, status
constexpr std::size_t kMeasurementIdOffset = 8;
constexpr std::size_t kLegacyFrameIdOffset = 10;
constexpr std::size_t kLegacyEncoderOffset = 12;
constexpr std::size_t kColumnStatusOffset = 10;
constexpr std::size_t kFrameIdOffset = 2;             // in the packet header
constexpr std::size_t kInitializationIdOffset = 4;    // u24
constexpr std::size_t kSerialNumberOffset = 7;        // u40
constexpr uint16_t kLidarPacketType = 1;
constexpr uint32_t kLegacyValidColumn = 0xFFFFFFFFu;
constexpr uint32_t kLegacyTicksPerRevolution = 90112;
constexpr uint64_t kMaxSerialNumber = (uint64_t{1} << 40) - 1;

// Per-pixel writers, one per layout, mirroring the decoder's; the profile is
// chosen once per packet.
struct ScanFields {
  const uint32_t* range;
  const uint32_t* range2;
  const uint8_t* reflectivity;
  const uint8_t* reflectivity2;
  const uint16_t* signal;
  const uint16_t* signal2;
  const uint16_t* near_ir;
};

// LEGACY and RNG19_RFL8_SIG16_NIR16: u32 range word (20 or 19 bits, flags 0),
// reflectivity @4, signal @6, near-IR @8.
template <bool Legacy>
struct TwelveBytePixel {
  static constexpr bool kLegacy = Legacy;
  static constexpr std::size_t kBytes = 12;
  static void encode(const ScanFields& fields, std::size_t i, uint8_t* pixel) {
    writeLittleEndian<uint32_t>(pixel, fields.range[i]);
    pixel[4] = fields.reflectivity[i];
    writeLittleEndian<uint16_t>(pixel + 6, fields.signal[i]);
    writeLittleEndian<uint16_t>(pixel + 8, fields.near_ir[i]);
  }
};
using LegacyPixel = TwelveBytePixel<true>;
using Rng19Rfl8Sig16Nir16Pixel = TwelveBytePixel<false>;

// Range word with reflectivity in its top byte, twice; signals; near-IR.
struct Rng19Rfl8Sig16Nir16DualPixel {
  static constexpr bool kLegacy = false;
  static constexpr std::size_t kBytes = 16;
  static void encode(const ScanFields& fields, std::size_t i, uint8_t* pixel) {
    writeLittleEndian<uint32_t>(pixel, fields.range[i] | uint32_t{fields.reflectivity[i]} << 24);
    writeLittleEndian<uint32_t>(pixel + 4,
                                fields.range2[i] | uint32_t{fields.reflectivity2[i]} << 24);
    writeLittleEndian<uint16_t>(pixel + 8, fields.signal[i]);
    writeLittleEndian<uint16_t>(pixel + 10, fields.signal2[i]);
    writeLittleEndian<uint16_t>(pixel + 12, fields.near_ir[i]);
  }
};

// One u32: range / 8 in bits 0-14, reflectivity in 16-23, near-IR / 16 in 24-31.
struct Rng15Rfl8Nir8Pixel {
  static constexpr bool kLegacy = false;
  static constexpr std::size_t kBytes = 4;
  static void encode(const ScanFields& fields, std::size_t i, uint8_t* pixel) {
    writeLittleEndian<uint32_t>(pixel, (fields.range[i] >> 3) |
                                           uint32_t{fields.reflectivity[i]} << 16 |
                                           uint32_t{fields.near_ir[i]} >> 4 << 24);
  }
};

constexpr uint32_t kRng15RangeStep = 8;     // millimetres per count
constexpr uint32_t kRng15NearIrStep = 16;   // near-IR units per count
constexpr uint32_t kRng15MaxNearIr = 255 * kRng15NearIrStep;


uint64_t parseSerialNumber(const std::string& serial) {
  if (serial.empty()) return 0;
  const bool digits = serial.size() <= 13 && std::all_of(serial.begin(), serial.end(), [](char c) {
                        return c >= '0' && c <= '9';
                      });
  const uint64_t value = digits ? std::stoull(serial) : kMaxSerialNumber + 1;
  if (value > kMaxSerialNumber)
    throw std::invalid_argument("OusterPacketEncoder: serial number (prod_sn) \"" + serial +
                                "\" is not a number below 2^40, which packet headers carry");
  return value;
}

// Slicing by 8: table k advances the CRC over a byte followed by k zero bytes,
// so eight bytes take eight lookups and no loop-carried byte chain.
using Crc64Tables = std::array<std::array<uint64_t, 256>, 8>;
Crc64Tables makeCrc64Tables() {
  constexpr uint64_t kReflectedPolynomial = 0xC96C5795D7870F42ull;
  Crc64Tables tables{};
  for (uint64_t byte = 0; byte < 256; ++byte) {
    uint64_t crc = byte;
    for (int bit = 0; bit < 8; ++bit) crc = (crc >> 1) ^ ((crc & 1) ? kReflectedPolynomial : 0);
    tables[0][byte] = crc;
  }
  for (std::size_t k = 1; k < tables.size(); ++k)
    for (std::size_t byte = 0; byte < 256; ++byte)
      tables[k][byte] = (tables[k - 1][byte] >> 8) ^ tables[0][tables[k - 1][byte] & 0xFF];
  return tables;
}

[[noreturn]] void failPixel(const LidarScan& scan, std::size_t i, const char* field,
                            uint32_t value, const std::string& limit, UdpProfile profile) {
  throw PacketEncodingError("OusterPacketEncoder: " + std::string(field) + " " +
                            std::to_string(value) + " at row " +
                            std::to_string(i / scan.columns) + ", column " +
                            std::to_string(i % scan.columns) + " " + limit + " for " +
                            toString(profile) + " (see quantizeForProfile)");
}

}  // namespace

uint32_t validColumnStatus(UdpProfile profile) {
  return profile == UdpProfile::kLegacy ? kLegacyValidColumn : 1u;
}

uint32_t legacyEncoderCount(int column, int columns) {
  if (columns <= 0 || column < 0 || column >= columns)
    throw std::invalid_argument("legacyEncoderCount: column " + std::to_string(column) +
                                " is outside [0, " + std::to_string(columns) + ")");
  return static_cast<uint32_t>(uint64_t{kLegacyTicksPerRevolution} * column / columns);
}

uint32_t maxRangeMillimetres(UdpProfile profile) {
  switch (profile) {
    case UdpProfile::kLegacy: return (1u << 20) - 1;
    case UdpProfile::kRng19Rfl8Sig16Nir16:
    case UdpProfile::kRng19Rfl8Sig16Nir16Dual: return (1u << 19) - 1;
    case UdpProfile::kRng15Rfl8Nir8: return ((1u << 15) - 1) * kRng15RangeStep;
  }
  throw std::invalid_argument("unknown UDP profile");
}

void quantizeForProfile(LidarScan& scan, UdpProfile profile) {
  const uint32_t max_range = maxRangeMillimetres(profile);
  const bool rng15 = profile == UdpProfile::kRng15Rfl8Nir8;
  const auto quantizeRanges = [&](std::vector<uint32_t>& ranges) {
    for (uint32_t& range : ranges) {
      if (rng15) range = (range + kRng15RangeStep / 2) / kRng15RangeStep * kRng15RangeStep;
      if (range > max_range) range = 0;
    }
  };
  quantizeRanges(scan.range);
  quantizeRanges(scan.range2);
  // The fields the profile carries, as the decoder sizes them.
  const std::size_t pixels = static_cast<std::size_t>(scan.rows) * scan.columns;
  if (hasSecondReturn(profile)) {
    scan.range2.resize(pixels, 0);
    scan.reflectivity2.resize(pixels, 0);
    scan.signal2.resize(pixels, 0);
  } else {
    scan.range2.clear();
    scan.reflectivity2.clear();
    scan.signal2.clear();
  }
  if (hasSignal(profile)) scan.signal.resize(pixels, 0);
  else scan.signal.clear();
  // Column fields as the decoder stores them: the profile's valid status, an
  // encoder count only in LEGACY, and nothing for columns never sent.
  const bool legacy = profile == UdpProfile::kLegacy;
  for (int column = 0; column < scan.columns; ++column) {
    const bool valid = scan.status[column] != 0;
    scan.status[column] = valid ? validColumnStatus(profile) : 0u;
    scan.encoder_count[column] = valid && legacy ? legacyEncoderCount(column, scan.columns) : 0u;
    if (!valid) scan.timestamp_ns[column] = 0;
  }
  if (rng15)
    for (uint16_t& near_ir : scan.near_ir)
      near_ir = static_cast<uint16_t>(std::min<uint32_t>(
          (near_ir + kRng15NearIrStep / 2) / kRng15NearIrStep * kRng15NearIrStep, kRng15MaxNearIr));
}

uint64_t crc64(const uint8_t* data, std::size_t size) {
  static const Crc64Tables kTables = makeCrc64Tables();
  uint64_t crc = ~uint64_t{0};
  std::size_t i = 0;
  for (; i + 8 <= size; i += 8) {
    uint64_t word;
    std::memcpy(&word, data + i, sizeof(word));  // little-endian: byte 0 in the low bits
    crc ^= word;
    crc = kTables[7][crc & 0xFF] ^ kTables[6][(crc >> 8) & 0xFF] ^ kTables[5][(crc >> 16) & 0xFF] ^
          kTables[4][(crc >> 24) & 0xFF] ^ kTables[3][(crc >> 32) & 0xFF] ^
          kTables[2][(crc >> 40) & 0xFF] ^ kTables[1][(crc >> 48) & 0xFF] ^ kTables[0][crc >> 56];
  }
  for (; i < size; ++i) crc = kTables[0][(crc ^ data[i]) & 0xFF] ^ (crc >> 8);
  return ~crc;
}

OusterPacketEncoder::OusterPacketEncoder(const OusterMetadata& metadata)
    : format_(metadata),
      initialization_id_(metadata.initialization_id & 0xFFFFFFu),
      serial_number_(parseSerialNumber(metadata.serial)) {
  if (format_.columns() % format_.columnsPerPacket() != 0)
    throw std::invalid_argument("OusterPacketEncoder: columns_per_frame " +
                                std::to_string(format_.columns()) +
                                " is not a multiple of columns_per_packet " +
                                std::to_string(format_.columnsPerPacket()));
  const bool legacy = format_.profile() == UdpProfile::kLegacy;
  header_size_ = legacy ? 0 : kPacketHeaderSize;
  column_size_ = (legacy ? kLegacyColumnHeaderSize + 4 : kColumnHeaderSize) +
                 static_cast<std::size_t>(format_.rows()) * pixelBytes(format_.profile());
}

void OusterPacketEncoder::checkScan(const LidarScan& scan) const {
  const UdpProfile profile = format_.profile();
  const std::size_t pixels = static_cast<std::size_t>(format_.rows()) * format_.columns();
  const std::size_t columns = static_cast<std::size_t>(format_.columns());
  const auto requireSize = [&](const char* field, std::size_t size, std::size_t expected) {
    if (size != expected)
      throw PacketEncodingError("OusterPacketEncoder: scan field " + std::string(field) + " has " +
                                std::to_string(size) + " entries, " + toString(profile) +
                                " packets of " + std::to_string(format_.rows()) + "x" +
                                std::to_string(format_.columns()) + " need " +
                                std::to_string(expected));
  };
  if (scan.rows != format_.rows() || scan.columns != format_.columns())
    throw PacketEncodingError("OusterPacketEncoder: scan is " + std::to_string(scan.rows) + "x" +
                              std::to_string(scan.columns) + ", the metadata says " +
                              std::to_string(format_.rows()) + "x" +
                              std::to_string(format_.columns()));
  requireSize("range", scan.range.size(), pixels);
  requireSize("reflectivity", scan.reflectivity.size(), pixels);
  requireSize("near_ir", scan.near_ir.size(), pixels);
  if (hasSignal(profile)) requireSize("signal", scan.signal.size(), pixels);
  if (hasSecondReturn(profile)) {
    requireSize("range2", scan.range2.size(), pixels);
    requireSize("reflectivity2", scan.reflectivity2.size(), pixels);
    requireSize("signal2", scan.signal2.size(), pixels);
  }
  requireSize("timestamp_ns", scan.timestamp_ns.size(), columns);
  requireSize("status", scan.status.size(), columns);
  if (profile == UdpProfile::kLegacy) requireSize("encoder_count", scan.encoder_count.size(), columns);

  // Checked before any packet is handed out, so a bad scan writes nothing.
  const uint32_t max_range = maxRangeMillimetres(profile);
  const bool rng15 = profile == UdpProfile::kRng15Rfl8Nir8;
  const auto checkRanges = [&](const std::vector<uint32_t>& ranges, const char* field) {
    for (std::size_t i = 0; i < ranges.size(); ++i) {
      if (ranges[i] > max_range)
        failPixel(scan, i, field, ranges[i], "exceeds " + std::to_string(max_range) + " mm", profile);
      if (rng15 && ranges[i] % kRng15RangeStep != 0)
        failPixel(scan, i, field, ranges[i], "is not a multiple of 8 mm", profile);
    }
  };
  checkRanges(scan.range, "range");
  if (hasSecondReturn(profile)) checkRanges(scan.range2, "range2");
  if (rng15)
    for (std::size_t i = 0; i < scan.near_ir.size(); ++i)
      if (scan.near_ir[i] % kRng15NearIrStep != 0 || scan.near_ir[i] > kRng15MaxNearIr)
        failPixel(scan, i, "near_ir", scan.near_ir[i], "is not a multiple of 16 up to 4080",
                  profile);
}

template <typename PixelLayout>
void OusterPacketEncoder::encodePacket(const LidarScan& scan, int first_column,
                                       uint8_t* packet) const {
  const int rows = format_.rows();
  const int columns = format_.columns();
  const int columns_per_packet = format_.columnsPerPacket();
  const uint16_t frame_id = static_cast<uint16_t>(scan.frame_id);
  constexpr std::size_t kPixelsOffset =
      PixelLayout::kLegacy ? kLegacyColumnHeaderSize : kColumnHeaderSize;
  std::memset(packet, 0, format_.packetSize());
  if constexpr (!PixelLayout::kLegacy) {
    writeLittleEndian<uint16_t>(packet, kLidarPacketType);
    writeLittleEndian<uint16_t>(packet + kFrameIdOffset, frame_id);
    // u24 initialization id, then the u40 serial number: one 64-bit word.
    static_assert(kSerialNumberOffset == kInitializationIdOffset + 3);
    writeLittleEndian<uint64_t>(packet + kInitializationIdOffset,
                                uint64_t{initialization_id_} | serial_number_ << 24);
  }
  const ScanFields fields{scan.range.data(),         scan.range2.data(), scan.reflectivity.data(),
                          scan.reflectivity2.data(), scan.signal.data(), scan.signal2.data(),
                          scan.near_ir.data()};
  for (int c = 0; c < columns_per_packet; ++c) {
    const int column = first_column + c;
    uint8_t* column_bytes = packet + header_size_ + c * column_size_;
    const bool valid = scan.status[column] != 0;
    writeLittleEndian<uint64_t>(column_bytes, scan.timestamp_ns[column]);
    writeLittleEndian<uint16_t>(column_bytes + kMeasurementIdOffset, static_cast<uint16_t>(column));
    if constexpr (PixelLayout::kLegacy) {
      writeLittleEndian<uint16_t>(column_bytes + kLegacyFrameIdOffset, frame_id);
      writeLittleEndian<uint32_t>(column_bytes + kLegacyEncoderOffset, scan.encoder_count[column]);
      writeLittleEndian<uint32_t>(column_bytes + kPixelsOffset + rows * PixelLayout::kBytes,
                                  valid ? kLegacyValidColumn : 0u);
    } else {
      writeLittleEndian<uint16_t>(column_bytes + kColumnStatusOffset,
                                  valid ? static_cast<uint16_t>(scan.status[column] | 1u) : 0);
    }
  }
  // Row by row, so consecutive reads of the row-major scan are neighbours.
  for (int row = 0; row < rows; ++row) {
    const std::size_t row_start = static_cast<std::size_t>(row) * columns;
    for (int c = 0; c < columns_per_packet; ++c) {
      const int column = first_column + c;
      if (scan.status[column] == 0) continue;
      PixelLayout::encode(fields, row_start + column,
                          packet + header_size_ + c * column_size_ + kPixelsOffset +
                              row * PixelLayout::kBytes);
    }
  }
  if constexpr (!PixelLayout::kLegacy) {
    const std::size_t crc_offset = format_.packetSize() - sizeof(uint64_t);
    writeLittleEndian<uint64_t>(packet + crc_offset, crc64(packet, crc_offset));
  }
}

std::size_t OusterPacketEncoder::encode(const LidarScan& scan, const PacketCallback& on_packet) const {
  checkScan(scan);
  std::vector<uint8_t> packet(format_.packetSize());
  const int columns_per_packet = format_.columnsPerPacket();
  std::size_t sent = 0;
  for (int first_column = 0; first_column < format_.columns(); first_column += columns_per_packet) {
    bool any_valid = false;
    uint64_t latest_timestamp_ns = 0;
    for (int column = first_column; column < first_column + columns_per_packet; ++column) {
      any_valid = any_valid || scan.status[column] != 0;
      latest_timestamp_ns = std::max(latest_timestamp_ns, scan.timestamp_ns[column]);
    }
    if (!any_valid) continue;
    switch (format_.profile()) {
      case UdpProfile::kLegacy: encodePacket<LegacyPixel>(scan, first_column, packet.data()); break;
      case UdpProfile::kRng19Rfl8Sig16Nir16:
        encodePacket<Rng19Rfl8Sig16Nir16Pixel>(scan, first_column, packet.data());
        break;
      case UdpProfile::kRng19Rfl8Sig16Nir16Dual:
        encodePacket<Rng19Rfl8Sig16Nir16DualPixel>(scan, first_column, packet.data());
        break;
      case UdpProfile::kRng15Rfl8Nir8:
        encodePacket<Rng15Rfl8Nir8Pixel>(scan, first_column, packet.data());
        break;
    }
    on_packet(packet.data(), packet.size(), latest_timestamp_ns);
    ++sent;
  }
  return sent;
}

std::vector<std::vector<uint8_t>> OusterPacketEncoder::encode(const LidarScan& scan) const {
  std::vector<std::vector<uint8_t>> packets;
  encode(scan, [&](const uint8_t* packet, std::size_t size, uint64_t) {
    packets.emplace_back(packet, packet + size);
  });
  return packets;
}

}  // namespace range_image_mapping
