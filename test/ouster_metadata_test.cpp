// Ouster metadata JSON: the real files of both formats, the manufacturer's
// defaults, and every kind of malformed input.
#include "range_image_mapping/ouster_metadata.h"

#include "test_data.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace range_image_mapping {
namespace {

constexpr double kDegree = M_PI / 180.0;

// ------------------------------------------------------------ synthetic JSON

using Fields = std::vector<std::pair<std::string, std::string>>;  // key, raw JSON value
const std::string kRemove = "<remove>";

std::string objectText(const Fields& fields) {
  std::string text = "{";
  for (const auto& [key, value] : fields) {
    if (text.size() > 1) text += ", ";
    text += "\"" + key + "\": " + value;
  }
  return text + "}";
}

std::string numberList(int count, double first, double step) {
  std::ostringstream text;
  text << "[";
  for (int i = 0; i < count; ++i) text << (i ? ", " : "") << first + i * step;
  text << "]";
  return text.str();
}

// Replaces or removes fields (kRemove) of the first section holding the key;
// keys found nowhere are added to the first section.
void applyChanges(std::vector<Fields*> sections, const std::map<std::string, std::string>& changes) {
  for (const auto& [key, value] : changes) {
    bool found = false;
    for (Fields* fields : sections) {
      for (auto it = fields->begin(); it != fields->end(); ++it) {
        if (it->first != key) continue;
        if (value == kRemove) fields->erase(it);
        else it->second = value;
        found = true;
        break;
      }
      if (found) break;
    }
    if (!found && value != kRemove) sections.front()->emplace_back(key, value);
  }
}

// 16 beams, 1024x10, RNG19 single return: altitudes 15, 13, ..., -15 degrees,
// azimuths 3, 2.75, ...; the flat (firmware 2.x) layout.
Fields defaultBeamFields() {
  return {{"beam_altitude_angles", numberList(16, 15, -2)},
          {"beam_azimuth_angles", numberList(16, 3, -0.25)},
          {"lidar_origin_to_beam_origin_mm", "15.806"}};
}
Fields defaultFormatFields() {
  return {{"columns_per_frame", "1024"},
          {"columns_per_packet", "16"},
          {"pixels_per_column", "16"},
          {"pixel_shift_by_row", numberList(16, 12, 0)},
          {"column_window", "[0, 1023]"},
          {"udp_profile_lidar", "\"RNG19_RFL8_SIG16_NIR16\""}};
}
const std::string kLidarToSensor = "[-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 36.18, 0, 0, 0, 1]";

std::string flatMetadata(const std::map<std::string, std::string>& changes = {}) {
  Fields top = defaultBeamFields();
  top.insert(top.end(), {{"lidar_mode", "\"1024x10\""},
                         {"prod_line", "\"OS-1-16-TEST\""},
                         {"build_rev", "\"v2.3.0\""},
                         {"prod_sn", "\"122201000998\""},
                         {"udp_port_lidar", "7502"},
                         {"lidar_to_sensor_transform", kLidarToSensor}});
  Fields format = defaultFormatFields();
  applyChanges({&top, &format}, changes);
  top.emplace_back("data_format", objectText(format));
  return objectText(top);
}

// The same sensor in the nested layout of newer firmware and the SDK.
std::string nestedMetadata(const std::map<std::string, std::string>& changes = {}) {
  Fields beams = defaultBeamFields();
  Fields format = defaultFormatFields();
  Fields config = {{"lidar_mode", "\"1024x10\""},
                   {"udp_port_lidar", "7502"},
                   {"udp_profile_lidar", "\"RNG19_RFL8_SIG16_NIR16\""}};
  Fields sensor_info = {{"prod_line", "\"OS-1-16-TEST\""},
                        {"build_rev", "\"v2.3.0\""},
                        {"prod_sn", "122201000998"}};  // a number in some firmware
  Fields lidar_intrinsics = {{"lidar_to_sensor_transform", kLidarToSensor}};
  applyChanges({&beams, &format, &config, &sensor_info, &lidar_intrinsics}, changes);
  return objectText({{"beam_intrinsics", objectText(beams)},
                     {"lidar_data_format", objectText(format)},
                     {"config_params", objectText(config)},
                     {"sensor_info", objectText(sensor_info)},
                     {"lidar_intrinsics", objectText(lidar_intrinsics)}});
}

void expectSameIntrinsics(const LidarIntrinsics& a, const LidarIntrinsics& b) {
  EXPECT_EQ(a.rows, b.rows);
  EXPECT_EQ(a.columns, b.columns);
  EXPECT_EQ(a.altitude_rad, b.altitude_rad);
  EXPECT_EQ(a.azimuth_offset_rad, b.azimuth_offset_rad);
  EXPECT_EQ(a.beam_origin_radius_m, b.beam_origin_radius_m);
  EXPECT_EQ(a.beam_origin_z_m, b.beam_origin_z_m);
  EXPECT_EQ(a.pixel_shift_by_row, b.pixel_shift_by_row);
  EXPECT_TRUE(a.lidar_to_sensor.isApprox(b.lidar_to_sensor, 0.0));
  EXPECT_EQ(a.column_window, b.column_window);
  EXPECT_EQ(a.sensor_model, b.sensor_model);
}

// ------------------------------------------------------------ synthetic metadata

TEST(OusterMetadata, FlatFormatConvertsUnits) {
  const OusterMetadata metadata = parseOusterMetadata(flatMetadata());
  const LidarIntrinsics& intrinsics = metadata.intrinsics;
  EXPECT_EQ(metadata.profile, UdpProfile::kRng19Rfl8Sig16Nir16);
  EXPECT_EQ(metadata.pixels_per_column, 16);
  EXPECT_EQ(metadata.columns_per_frame, 1024);
  EXPECT_EQ(metadata.columns_per_packet, 16);
  EXPECT_EQ(metadata.frequency_hz, 10.0);
  EXPECT_EQ(metadata.lidar_mode, "1024x10");
  EXPECT_EQ(metadata.prod_line, "OS-1-16-TEST");
  EXPECT_EQ(metadata.firmware, "v2.3.0");
  EXPECT_EQ(metadata.serial, "122201000998");
  EXPECT_EQ(metadata.json, flatMetadata());
  ASSERT_EQ(intrinsics.rows, 16);
  ASSERT_EQ(intrinsics.columns, 1024);
  for (int v = 0; v < 16; ++v) {
    EXPECT_NEAR(intrinsics.altitude_rad[v], (15 - 2 * v) * kDegree, 1e-12) << v;
    // Ouster measures beam azimuth against the encoder direction: the sign flips.
    EXPECT_NEAR(intrinsics.azimuth_offset_rad[v], -(3 - 0.25 * v) * kDegree, 1e-12) << v;
  }
  EXPECT_NEAR(intrinsics.beam_origin_radius_m, 0.015806, 1e-12);
  EXPECT_EQ(intrinsics.beam_origin_z_m, 0.0);
  EXPECT_EQ(intrinsics.pixel_shift_by_row, std::vector<int>(16, 12));
  EXPECT_EQ(intrinsics.column_window, (std::array<int, 2>{0, 1023}));
  EXPECT_EQ(intrinsics.sensor_model, "OS-1-16-TEST");
  EXPECT_NEAR(intrinsics.lidar_to_sensor.translation().z(), 0.03618, 1e-12);
  EXPECT_EQ(intrinsics.lidar_to_sensor.linear(), Eigen::Vector3d(-1, -1, 1).asDiagonal().toDenseMatrix());
}

TEST(OusterMetadata, NestedFormatMatchesFlat) {
  const OusterMetadata flat = parseOusterMetadata(flatMetadata());
  const OusterMetadata nested = parseOusterMetadata(nestedMetadata());
  expectSameIntrinsics(flat.intrinsics, nested.intrinsics);
  EXPECT_EQ(nested.profile, flat.profile);
  EXPECT_EQ(nested.serial, "122201000998");
  EXPECT_EQ(nested.prod_line, flat.prod_line);
  EXPECT_EQ(nested.udp_port_lidar, 7502);
}

TEST(OusterMetadata, ProfileAndPortsFromConfigParams) {
  // Without lidar_data_format.udp_profile_lidar the config_params one counts.
  const OusterMetadata metadata = parseOusterMetadata(nestedMetadata(
      {{"udp_profile_lidar", kRemove}, {"columns_per_packet", kRemove}, {"udp_port_lidar", "53750"}}));
  EXPECT_EQ(metadata.profile, UdpProfile::kRng19Rfl8Sig16Nir16);  // config_params still has it
  EXPECT_EQ(metadata.columns_per_packet, 16);
  EXPECT_EQ(metadata.udp_port_lidar, 53750);
  EXPECT_EQ(metadata.udp_port_imu, 7503);
}

TEST(OusterMetadata, BeamToLidarTransformWins) {
  const OusterMetadata metadata = parseOusterMetadata(nestedMetadata(
      {{"beam_to_lidar_transform", "[1, 0, 0, 27.116, 0, 1, 0, 0, 0, 0, 1, -4.5, 0, 0, 0, 1]"}}));
  EXPECT_NEAR(metadata.intrinsics.beam_origin_radius_m, 0.027116, 1e-12);
  EXPECT_NEAR(metadata.intrinsics.beam_origin_z_m, -0.0045, 1e-12);
}

TEST(OusterMetadata, DefaultsWhereFieldsAreAbsent) {
  // No data format at all, no origin offset, no transform, no product line.
  const OusterMetadata metadata = parseOusterMetadata(flatMetadata(
      {{"columns_per_frame", kRemove}, {"columns_per_packet", kRemove},
       {"pixels_per_column", kRemove}, {"pixel_shift_by_row", kRemove},
       {"column_window", kRemove}, {"udp_profile_lidar", kRemove},
       {"lidar_origin_to_beam_origin_mm", kRemove}, {"lidar_to_sensor_transform", kRemove},
       {"prod_line", kRemove}, {"udp_port_lidar", kRemove}, {"lidar_mode", "\"2048x10\""}}));
  EXPECT_EQ(metadata.profile, UdpProfile::kLegacy);
  EXPECT_EQ(metadata.columns_per_packet, 16);
  EXPECT_EQ(metadata.columns_per_frame, 2048);
  EXPECT_EQ(metadata.pixels_per_column, 16);
  EXPECT_EQ(metadata.udp_port_lidar, 7502);
  const LidarIntrinsics& intrinsics = metadata.intrinsics;
  EXPECT_EQ(intrinsics.column_window, (std::array<int, 2>{0, 2047}));
  EXPECT_EQ(intrinsics.pixel_shift_by_row,
            (std::vector<int>{36, 24, 12, 0, 36, 24, 12, 0, 36, 24, 12, 0, 36, 24, 12, 0}));
  EXPECT_NEAR(intrinsics.beam_origin_radius_m, 0.012163, 1e-12);
  EXPECT_EQ(intrinsics.sensor_model, "OS-unknown");
  EXPECT_NEAR(intrinsics.lidar_to_sensor.translation().z(), 0.03618, 1e-12);
  EXPECT_EQ(intrinsics.lidar_to_sensor.linear(), Eigen::Vector3d(-1, -1, 1).asDiagonal().toDenseMatrix());
}

TEST(OusterMetadata, BeamOriginDefaultsByProductLine) {
  for (const auto& [prod_line, millimetres] :
       std::vector<std::pair<std::string, double>>{{"\"OS-0-128\"", 27.67},
                                                   {"\"OS-1-64-U\"", 15.806},
                                                   {"\"OS-2-32-U0\"", 13.762},
                                                   {"\"OS1-64\"", 12.163}}) {
    const OusterMetadata metadata = parseOusterMetadata(
        flatMetadata({{"lidar_origin_to_beam_origin_mm", kRemove}, {"prod_line", prod_line}}));
    EXPECT_NEAR(metadata.intrinsics.beam_origin_radius_m, millimetres * 0.001, 1e-12) << prod_line;
  }
}

TEST(OusterMetadata, FrequencyFromLidarMode) {
  for (const auto& [mode, columns, hertz] :
       std::vector<std::tuple<std::string, int, double>>{{"512x10", 512, 10}, {"512x20", 512, 20},
                                                         {"1024x20", 1024, 20}, {"4096x5", 4096, 5}}) {
    const OusterMetadata metadata = parseOusterMetadata(flatMetadata(
        {{"lidar_mode", "\"" + mode + "\""}, {"columns_per_frame", std::to_string(columns)},
         {"column_window", "[0, " + std::to_string(columns - 1) + "]"}}));
    EXPECT_EQ(metadata.columns_per_frame, columns) << mode;
    EXPECT_EQ(metadata.frequency_hz, hertz) << mode;
  }
}

TEST(OusterMetadata, ProfileNamesRoundTrip) {
  for (const UdpProfile profile : {UdpProfile::kLegacy, UdpProfile::kRng19Rfl8Sig16Nir16,
                                   UdpProfile::kRng19Rfl8Sig16Nir16Dual, UdpProfile::kRng15Rfl8Nir8})
    EXPECT_EQ(udpProfileFromString(toString(profile)), profile);
  EXPECT_THROW(udpProfileFromString("FUSA_RNG15_RFL8_NIR8_DUAL"), MetadataError);
}

// ------------------------------------------------------------ malformed metadata

struct MalformedCase {
  const char* name;
  std::string json;
  std::string expected_message;  // a part of what()
};

std::vector<MalformedCase> malformedCases() {
  return {
      {"missing altitudes", flatMetadata({{"beam_altitude_angles", kRemove}}),
       "metadata: beam_altitude_angles is missing"},
      {"missing azimuths", nestedMetadata({{"beam_azimuth_angles", kRemove}}),
       "metadata: beam_azimuth_angles is missing"},
      {"empty altitudes", flatMetadata({{"beam_altitude_angles", "[]"}, {"pixels_per_column", kRemove}}),
       "beam_altitude_angles is empty"},
      {"altitudes not an array", flatMetadata({{"beam_altitude_angles", "\"up\""}}),
       "beam_altitude_angles must be an array of numbers"},
      {"altitude entry a string", flatMetadata({{"beam_altitude_angles",
                                                 "[1, 2, 3, \"x\", 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16]"}}),
       "beam_altitude_angles[3] must be a number"},
      {"altitude entry infinite", flatMetadata({{"beam_altitude_angles",
                                                 "[1e999, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16]"}}),
       "'1e999' is not a number"},  // JSON has no infinity
      {"64 altitudes for 128 pixels",
       flatMetadata({{"beam_altitude_angles", numberList(64, 10, -0.3)},
                     {"beam_azimuth_angles", numberList(128, 0, 0)},
                     {"pixel_shift_by_row", numberList(128, 0, 0)},
                     {"pixels_per_column", "128"}}),
       "metadata: beam_altitude_angles has 64 entries, pixels_per_column is 128"},
      {"azimuth count", flatMetadata({{"beam_azimuth_angles", numberList(15, 0, 0)}}),
       "beam_azimuth_angles has 15 entries, pixels_per_column is 16"},
      {"pixel shift count", flatMetadata({{"pixel_shift_by_row", numberList(17, 0, 0)}}),
       "pixel_shift_by_row has 17 entries, pixels_per_column is 16"},
      {"fractional pixel shift", flatMetadata({{"pixel_shift_by_row", numberList(16, 0.5, 0)}}),
       "pixel_shift_by_row[0] must be an integer"},
      {"zero pixels per column", flatMetadata({{"pixels_per_column", "0"}}),
       "pixels_per_column is 0, must be within [1, 1024]"},
      {"absurd pixels per column", flatMetadata({{"pixels_per_column", "100000"}}),
       "pixels_per_column is 100000, must be within [1, 1024]"},
      {"zero columns", flatMetadata({{"columns_per_frame", "0"}}),
       "columns_per_frame is 0, lidar_mode 1024x10 has 1024"},
      {"negative columns", nestedMetadata({{"columns_per_frame", "-1024"}}),
       "columns_per_frame is -1024"},
      {"columns disagree with mode", flatMetadata({{"columns_per_frame", "512"}}),
       "columns_per_frame is 512, lidar_mode 1024x10 has 1024"},
      {"zero columns per packet", flatMetadata({{"columns_per_packet", "0"}}),
       "columns_per_packet is 0, must be within [1, 1024]"},
      {"fractional columns per packet", flatMetadata({{"columns_per_packet", "16.5"}}),
       "columns_per_packet must be an integer"},
      {"unknown profile", flatMetadata({{"udp_profile_lidar", "\"RNG99_FANCY\""}}),
       "udp_profile_lidar 'RNG99_FANCY' is not supported"},
      {"profile not a string", nestedMetadata({{"udp_profile_lidar", "42"}}),
       "udp_profile_lidar must be a string"},
      {"lidar_mode garbage", flatMetadata({{"lidar_mode", "\"garbage\""}}),
       "lidar_mode 'garbage' is not one of"},
      {"lidar_mode without rate", flatMetadata({{"lidar_mode", "\"1024x\""}}),
       "lidar_mode '1024x' is not one of"},
      {"lidar_mode zero", flatMetadata({{"lidar_mode", "\"0x10\""}}), "lidar_mode '0x10'"},
      {"lidar_mode number", flatMetadata({{"lidar_mode", "1024"}}), "lidar_mode must be a string"},
      {"lidar_mode missing", nestedMetadata({{"lidar_mode", kRemove}}), "lidar_mode is missing"},
      {"window outside", flatMetadata({{"column_window", "[0, 1024]"}}),
       "column_window [0, 1024] must lie within [0, 1023]"},
      {"window with one entry", flatMetadata({{"column_window", "[5]"}}),
       "column_window has 1 entries, expected 2"},
      {"short transform", flatMetadata({{"lidar_to_sensor_transform", numberList(15, 0, 0)}}),
       "lidar_to_sensor_transform has 15 entries, expected 16"},
      {"not a rotation",
       flatMetadata({{"lidar_to_sensor_transform", "[2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]"}}),
       "lidar_to_sensor_transform rotation is not a rotation matrix"},
      {"not homogeneous",
       flatMetadata({{"lidar_to_sensor_transform", "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 0, 0, 1]"}}),
       "lidar_to_sensor_transform last row must be 0 0 0 1"},
      {"bad beam transform", nestedMetadata({{"beam_to_lidar_transform", "{}"}}),
       "beam_to_lidar_transform must be an array of numbers"},
      {"origin offset a string", flatMetadata({{"lidar_origin_to_beam_origin_mm", "\"15\""}}),
       "lidar_origin_to_beam_origin_mm must be a number"},
      {"port out of range", flatMetadata({{"udp_port_lidar", "70000"}}),
       "udp_port_lidar is 70000, must be within [0, 65535]"},
      {"product line a list", flatMetadata({{"prod_line", "[1]"}}), "prod_line must be a string"},
      {"unparsable", "{\"beam_altitude_angles\": [1, 2", "metadata: not valid JSON"},
      {"empty text", "", "metadata: not valid JSON"},
      {"trailing garbage", flatMetadata() + " }", "metadata: not valid JSON"},
      {"NaN literal", flatMetadata({{"lidar_origin_to_beam_origin_mm", "NaN"}}),
       "metadata: not valid JSON"},
      {"duplicate key", "{\"lidar_mode\": \"1024x10\", \"lidar_mode\": \"512x10\"}",
       "metadata: not valid JSON"},
      {"top level array", "[1, 2, 3]", "metadata: top level must be a JSON object"},
      {"deep nesting", std::string(100000, '['), "metadata: not valid JSON"},
  };
}

TEST(OusterMetadata, MalformedInputNamesTheField) {
  for (const MalformedCase& malformed : malformedCases()) {
    SCOPED_TRACE(malformed.name);
    try {
      parseOusterMetadata(malformed.json);
      ADD_FAILURE() << "accepted: " << malformed.json.substr(0, 200);
    } catch (const MetadataError& error) {
      EXPECT_NE(std::string(error.what()).find(malformed.expected_message), std::string::npos)
          << "message: " << error.what() << "\nexpected to contain: " << malformed.expected_message;
    }
  }
}

TEST(OusterMetadata, ImpossibleAnglesFailIntrinsicsValidation) {
  // 95 degrees parses as a number but no beam points there.
  const std::string json = flatMetadata(
      {{"beam_altitude_angles", "[95, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16]"}});
  try {
    parseOusterMetadata(json);
    ADD_FAILURE() << "95 degree altitude accepted";
  } catch (const IntrinsicsError& error) {
    EXPECT_NE(std::string(error.what()).find("altitude_rad"), std::string::npos) << error.what();
  }
}

TEST(OusterMetadata, MissingFileNamesThePath) {
  const std::string path = "/nonexistent/directory/metadata.json";
  try {
    loadOusterMetadata(path);
    ADD_FAILURE() << "missing file accepted";
  } catch (const MetadataError& error) {
    EXPECT_NE(std::string(error.what()).find(path), std::string::npos) << error.what();
  }
}

// ------------------------------------------------------------ real files

struct RealFile {
  const char* name;
  UdpProfile profile;
  int rows;
  int columns;
  double frequency_hz;
  double beam_origin_mm;
  double lidar_to_sensor_z_mm;
  const char* prod_line;
};

// Values from the data folder's SOURCE.md tables.
const RealFile kRealFiles[] = {
    {"OS-0-128-U1_v2.3.0_1024x10.json", UdpProfile::kRng15Rfl8Nir8, 128, 1024, 10, 27.67, 36.18, "OS-0-128"},
    {"OS-1-128_v2.3.0_1024x10.json", UdpProfile::kRng15Rfl8Nir8, 128, 1024, 10, 15.806, 36.18, "OS-1-128"},
    {"OS-2-128-U1_v2.3.0_1024x10.json", UdpProfile::kRng19Rfl8Sig16Nir16, 128, 1024, 10, 13.762, 78.296, "OS-2-128"},
    {"OS-0-32-U1_v2.2.0_1024x10.json", UdpProfile::kRng19Rfl8Sig16Nir16Dual, 32, 1024, 10, 27.67, 36.18, "OS-0-32-U1"},
    {"OS-1-32-G_v2.1.1_1024x10.json", UdpProfile::kLegacy, 32, 1024, 10, 15.806, 36.18, "OS-1-32-G"},
    {"OS-2-32-U0_v2.0.0_1024x10.json", UdpProfile::kLegacy, 32, 1024, 20, 13.762, 74.296, "OS-2-32-U0"},
    {"crc_test.json", UdpProfile::kRng15Rfl8Nir8, 128, 512, 10, 27.116, 38.195, "OS-0-128"},
};

TEST(OusterMetadata, RealFilesOfBothFormats) {
  for (const RealFile& file : kRealFiles) {
    SCOPED_TRACE(file.name);
    RIM_REQUIRE_DATA(path, std::string("ouster-pcaps/") + file.name);
    const OusterMetadata metadata = loadOusterMetadata(path);
    EXPECT_EQ(metadata.profile, file.profile);
    EXPECT_EQ(metadata.pixels_per_column, file.rows);
    EXPECT_EQ(metadata.columns_per_frame, file.columns);
    EXPECT_EQ(metadata.columns_per_packet, 16);
    EXPECT_EQ(metadata.frequency_hz, file.frequency_hz);
    EXPECT_EQ(metadata.prod_line, file.prod_line);
    EXPECT_EQ(metadata.udp_port_lidar, 7502);
    const LidarIntrinsics& intrinsics = metadata.intrinsics;
    EXPECT_EQ(intrinsics.rows, file.rows);
    EXPECT_EQ(intrinsics.columns, file.columns);
    EXPECT_EQ(intrinsics.sensor_model, file.prod_line);
    EXPECT_NEAR(intrinsics.beam_origin_radius_m, file.beam_origin_mm * 0.001, 1e-12);
    EXPECT_NEAR(intrinsics.lidar_to_sensor.translation().z(), file.lidar_to_sensor_z_mm * 0.001, 1e-12);
    EXPECT_EQ(intrinsics.column_window, (std::array<int, 2>{0, file.columns - 1}));
    EXPECT_EQ(intrinsics.pixel_shift_by_row.size(), static_cast<std::size_t>(file.rows));
    // Row 0 is the top beam.
    EXPECT_GT(intrinsics.altitude_rad.front(), intrinsics.altitude_rad.back());
  }
}

TEST(OusterMetadata, Os0BeamAnglesInRadians) {
  RIM_REQUIRE_DATA(path, "ouster-pcaps/OS-0-128-U1_v2.3.0_1024x10.json");
  const OusterMetadata metadata = loadOusterMetadata(path);
  // SOURCE.md: alt[0] = +45.75, alt[127] = -46.26 degrees.
  EXPECT_NEAR(metadata.intrinsics.altitude_rad[0], 45.75 * kDegree, 1e-12);
  EXPECT_NEAR(metadata.intrinsics.altitude_rad[127], -46.26 * kDegree, 1e-12);
}

TEST(OusterMetadata, NestedFileWithWrappingWindowAndOwnPort) {
  RIM_REQUIRE_DATA(path, "ouster-pcaps/windowed_frame2_0.json");
  const OusterMetadata metadata = loadOusterMetadata(path);
  EXPECT_EQ(metadata.intrinsics.column_window, (std::array<int, 2>{370, 85}));
  EXPECT_EQ(metadata.intrinsics.columnWindowWidth(), 512 - 370 + 86);
  EXPECT_EQ(metadata.udp_port_lidar, 53750);
  EXPECT_EQ(metadata.serial, "992108000265");
  EXPECT_EQ(metadata.firmware, "v2.3.0");
}

TEST(OusterMetadata, NestedFileKeepsNegativeShifts) {
  RIM_REQUIRE_DATA(path, "ouster-pcaps/crc_test.json");
  const OusterMetadata metadata = loadOusterMetadata(path);
  const std::vector<int>& shifts = metadata.intrinsics.pixel_shift_by_row;
  ASSERT_EQ(shifts.size(), 128u);
  EXPECT_EQ((std::vector<int>(shifts.begin(), shifts.begin() + 3)), (std::vector<int>{15, 5, -5}));
}

TEST(OusterMetadata, ReducedFileGetsManufacturerDefaults) {
  RIM_REQUIRE_DATA(path, "ouster-pcaps/OS-1-64_sensor_config_reduced.json");
  const OusterMetadata metadata = loadOusterMetadata(path);
  EXPECT_EQ(metadata.profile, UdpProfile::kLegacy);
  EXPECT_EQ(metadata.pixels_per_column, 64);
  EXPECT_EQ(metadata.columns_per_frame, 1024);
  EXPECT_EQ(metadata.columns_per_packet, 16);
  const LidarIntrinsics& intrinsics = metadata.intrinsics;
  std::vector<int> expected_shifts;
  for (int group = 0; group < 16; ++group) expected_shifts.insert(expected_shifts.end(), {18, 12, 6, 0});
  EXPECT_EQ(intrinsics.pixel_shift_by_row, expected_shifts);
  EXPECT_NEAR(intrinsics.beam_origin_radius_m, 0.012163, 1e-12);
  EXPECT_EQ(intrinsics.lidar_to_sensor.linear(), Eigen::Vector3d(-1, -1, 1).asDiagonal().toDenseMatrix());
  EXPECT_TRUE(intrinsics.lidar_to_sensor.translation().isApprox(Eigen::Vector3d(0, 0, 0.03618)));
  EXPECT_EQ(intrinsics.column_window, (std::array<int, 2>{0, 1023}));
  EXPECT_EQ(intrinsics.sensor_model, "OS-unknown");
}

}  // namespace
}  // namespace range_image_mapping
