#include "range_image_mapping/sensor_catalog.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <numeric>

namespace range_image_mapping {
namespace {

constexpr double kDegree = M_PI / 180.0;

// One laser as a calibration file lists it, in degrees: elevation, and the
// azimuth offset in this model's sense (added to the encoder angle, counter-
// clockwise seen from above). Velodyne's rot_correction is subtracted from a
// clockwise azimuth, so it keeps its sign; Hesai and RoboSense add their
// horizontal correction to a clockwise azimuth, so theirs changes sign.
struct Laser {
  double elevation_deg;
  double azimuth_offset_deg;
};

struct Entry {
  const char* name;
  const char* maker;
  const char* source;
  std::vector<const char*> aliases;
  int columns;
  std::vector<Laser> lasers;  // laser-id order; the rows come out sorted from the highest beam down
};

constexpr const char* kKittiName = "HDL-64E";

std::vector<Laser> withoutOffsets(const std::vector<double>& elevations_deg) {
  std::vector<Laser> lasers;
  for (const double elevation : elevations_deg) lasers.push_back({elevation, 0.0});
  return lasers;
}

// Clockwise horizontal corrections (Hesai, RoboSense) as this model's offsets.
std::vector<Laser> clockwiseOffsets(std::vector<Laser> lasers) {
  for (Laser& laser : lasers) laser.azimuth_offset_deg = -laser.azimuth_offset_deg;
  return lasers;
}

std::vector<Laser> evenlySpaced(int count, double top_deg, double step_deg) {
  std::vector<double> elevations;
  for (int i = 0; i < count; ++i) elevations.push_back(top_deg - i * step_deg);
  return withoutOffsets(elevations);
}

// Columns: one per firing of all lasers in a revolution at 10 Hz. Velodyne
// fires on a clock (VLP-16 and VLP-32C every 55.296 us, HDL-32E every
// 46.08 us: 1808 and 2170 firings per revolution, the data sheets' rounded
// 0.2 and 0.16 deg); Hesai and RoboSense on the encoder (0.2 deg, XT-32
// 0.18 deg).
const std::vector<Entry>& entries() {
  static const std::vector<Entry> table{
      {"VLP-16", "Velodyne", "VLP-16 data sheet and manual: 16 lasers, +-15 deg in 2 deg steps, firing order",
       {"VLP16", "Puck"}, 1808,
       withoutOffsets({-15, 1, -13, 3, -11, 5, -9, 7, -7, 9, -5, 11, -3, 13, -1, 15})},
      {"VLP-32C", "Velodyne",
       "VLP-32C manual's laser table (vert_correction, rot_correction): +15 to -25 deg, densest 0.33 deg at the horizon",
       {"VLP32C", "UltraPuck"}, 1808,
       {{-25, -1.4},     {-1, 4.2},      {-1.667, -1.4}, {-15.639, 1.4}, {-11.31, -1.4}, {0, 1.4},
        {-0.667, -4.2},  {-8.843, 1.4},  {-7.254, -1.4}, {0.333, 4.2},   {-0.333, -1.4}, {-6.148, 1.4},
        {-5.333, -4.2},  {1.333, 1.4},   {0.667, -4.2},  {-4, 1.4},      {-4.667, -1.4}, {1.667, 4.2},
        {1, -1.4},       {-3.667, 4.2},  {-3.333, -4.2}, {3.333, 1.4},   {2.333, -1.4},  {-2.667, 1.4},
        {-3, -1.4},      {7, 1.4},       {4.667, -1.4},  {-2.333, 4.2},  {-2, -4.2},     {15, 1.4},
        {10.333, -1.4},  {-1.333, 1.4}}},
      {"HDL-32E", "Velodyne", "HDL-32E manual: 32 lasers, +10.67 to -30.67 deg in 1.33 deg steps, firing order",
       {"HDL32E", "HDL32"}, 2170,
       withoutOffsets({-30.67, -9.33, -29.33, -8,     -28,    -6.67, -26.67, -5.33, -25.33, -4,    -24,
                       -2.67,  -22.67, -1.33, -21.33, 0,      -20,   1.33,   -18.67, 2.67,  -17.33, 4,
                       -16,    5.33,  -14.67, 6.67,   -13.33, 8,     -12,    9.33,   -10.67, 10.67})},
      // No laser table: kittiHdl64Intrinsics.
      {"HDL-64E", "Velodyne", "KITTI's HDL-64E seen from its Velodyne frame: 64 even rows, +3 to -25 deg (synthetic)",
       {"HDL64E", "HDL64", "KITTI"}, 2048, {}},
      {"PandarXT-32", "Hesai", "PandarXT-32 data sheet: 32 channels, +15 to -16 deg in 1 deg steps, one azimuth",
       {"XT32", "PandarXT32"}, 2000, evenlySpaced(32, 15.0, 1.0)},
      {"Pandar64", "Hesai",
       "a Pandar64 unit's angle correction file (Hesai SDK): +15 to -25 deg, densest 0.17 deg, azimuths +-1.1 to +-5.6 deg",
       {"P64"}, 1800,
       clockwiseOffsets(
           {{14.838, 1.091},  {10.983, 1.089},  {8.003, 1.087},   {5.017, 1.079},   {3.022, -1.123},
            {1.999, -1.119},  {1.813, 5.525},   {1.674, 3.301},   {1.509, -3.347},  {1.318, 1.077},
            {1.140, -5.545},  {0.981, -1.129},  {0.801, 5.520},   {0.664, 3.300},   {0.506, -3.350},
            {0.307, 1.074},   {0.168, -5.556},  {-0.024, -1.122}, {-0.179, 5.537},  {-0.348, 3.301},
            {-0.531, -3.347}, {-0.722, 1.075},  {-0.870, -5.564}, {-1.044, -1.133}, {-1.217, 5.543},
            {-1.355, 3.314},  {-1.550, -3.356}, {-1.716, 1.082},  {-1.875, -5.566}, {-2.058, -1.136},
            {-2.241, 5.552},  {-2.376, 3.317},  {-2.546, -3.359}, {-2.732, 1.074},  {-2.872, -5.572},
            {-3.087, -1.131}, {-3.230, 5.557},  {-3.389, 3.326},  {-3.543, -3.366}, {-3.757, 1.085},
            {-3.892, -5.583}, {-4.094, -1.142}, {-4.241, 5.571},  {-4.425, 3.340},  {-4.574, -3.365},
            {-4.750, 1.086},  {-4.900, -5.588}, {-5.090, -1.148}, {-5.248, 5.581},  {-5.425, 3.339},
            {-5.596, -3.371}, {-5.780, 1.082},  {-5.878, -5.607}, {-6.109, -1.154}, {-7.097, -1.149},
            {-8.090, -1.165}, {-9.080, 1.103},  {-10.084, 1.102}, {-11.052, 1.107}, {-12.018, 1.111},
            {-13.023, -1.174}, {-13.951, -1.167}, {-18.913, -1.160}, {-24.883, -1.159}})},
      {"RS-LiDAR-16", "RoboSense", "RS-LiDAR-16 data sheet: 16 channels, +-15 deg in 2 deg steps, channel order",
       {"RS16", "RSLiDAR16"}, 1800, withoutOffsets({-15, -13, -11, -9, -7, -5, -3, -1, 15, 13, 11, 9, 7, 5, 3, 1})},
      {"RS-LiDAR-32", "RoboSense",
       "an RS-LiDAR-32 unit's angle.csv (RoboSense ROS driver): +15 to -25 deg, densest 0.33 deg, azimuths +-2.3 to "
       "+-8.4 deg",
       {"RS32", "RSLiDAR32"}, 1800,
       clockwiseOffsets({{-10.333, 8.193}, {0.333, -8.111},  {-6.477, 8.341},  {0.000, -2.968},  {2.315, 8.245},
                         {-0.333, 2.252},  {3.280, -7.497},  {-0.667, 7.771},  {4.649, 8.181},   {1.667, -8.149},
                         {6.982, -7.187},  {1.333, -2.929},  {10.350, 8.391},  {1.000, 2.242},   {14.983, -7.046},
                         {0.667, 7.701},   {-25.029, -7.297}, {-2.333, -7.917}, {-14.688, -7.253}, {-2.667, -2.893},
                         {-7.963, -6.890}, {-3.000, 2.455},  {-5.443, -6.902}, {-3.333, 7.735},  {-3.703, -8.001},
                         {-0.946, -8.123}, {-3.982, -2.753}, {-1.351, -2.978}, {-4.333, 2.570},  {-1.667, 2.385},
                         {-4.667, 7.945},  {-1.964, 7.655}})},
  };
  return table;
}

LidarIntrinsics intrinsicsOf(const Entry& entry, int columns) {
  if (entry.lasers.empty()) return kittiHdl64Intrinsics(columns);
  std::vector<Laser> rows = entry.lasers;
  std::stable_sort(rows.begin(), rows.end(),
                   [](const Laser& a, const Laser& b) { return a.elevation_deg > b.elevation_deg; });
  LidarIntrinsics intrinsics;
  intrinsics.rows = static_cast<int>(rows.size());
  intrinsics.columns = columns;
  for (const Laser& laser : rows) {
    intrinsics.altitude_rad.push_back(laser.elevation_deg * kDegree);
    intrinsics.azimuth_offset_rad.push_back(laser.azimuth_offset_deg * kDegree);
  }
  intrinsics.pixel_shift_by_row.assign(rows.size(), 0);
  intrinsics.sensor_model = entry.name;
  intrinsics.validate();
  return intrinsics;
}

std::string comparable(const std::string& name) {
  std::string key;
  for (const char c : name)
    if (c != '-' && c != '_' && c != ' ') key += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return key;
}

}  // namespace

const std::vector<CatalogSensor>& sensorCatalog() {
  static const std::vector<CatalogSensor> catalog = [] {
    std::vector<CatalogSensor> sensors;
    for (const Entry& entry : entries())
      sensors.push_back({entry.name, entry.maker, entry.source, intrinsicsOf(entry, entry.columns)});
    return sensors;
  }();
  return catalog;
}

std::string sensorCatalogNames() {
  std::string names;
  for (const Entry& entry : entries()) names += (names.empty() ? "" : ", ") + std::string(entry.name);
  return names;
}

std::optional<LidarIntrinsics> catalogSensor(const std::string& name) {
  const std::string key = comparable(name);
  if (key.empty()) return std::nullopt;
  for (std::size_t i = 0; i < entries().size(); ++i) {
    const Entry& entry = entries()[i];
    bool match = comparable(entry.name) == key;
    for (const char* alias : entry.aliases) match |= comparable(alias) == key;
    if (match) return sensorCatalog()[i].intrinsics;
  }
  return std::nullopt;
}

LidarIntrinsics kittiHdl64Intrinsics(int columns) {
  LidarIntrinsics intrinsics = LidarIntrinsics::synthetic(64, columns, 3.0 * kDegree, -25.0 * kDegree);
  intrinsics.sensor_model = std::string(kKittiName) + " (synthetic)";
  return intrinsics;
}

}  // namespace range_image_mapping
