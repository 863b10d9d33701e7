// The sensor model on real Ouster captures: Pi inverts Pi^-1 on every valid
// pixel, and unprojected scans land on the manufacturer's reference map.
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/io/ply.h"
#include "range_image_mapping/ouster_packet.h"
#include "test_data.h"

#include <gtest/gtest.h>
#include <nanoflann.hpp>

#include <algorithm>
#include <cstdlib>

namespace range_image_mapping {
namespace {

struct Capture {
  const char* pcap;
  const char* metadata;
};

// Every capture in shared/data with a complete scan.
const Capture kCaptures[] = {
    {"ouster-pcaps/OS-0-128-U1_v2.3.0_1024x10.pcap", "ouster-pcaps/OS-0-128-U1_v2.3.0_1024x10.json"},
    {"ouster-pcaps/OS-0-32-U1_v2.2.0_1024x10.pcap", "ouster-pcaps/OS-0-32-U1_v2.2.0_1024x10.json"},
    {"ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap", "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json"},
    {"ouster-pcaps/OS-1-32-G_v2.1.1_1024x10.pcap", "ouster-pcaps/OS-1-32-G_v2.1.1_1024x10.json"},
    {"ouster-pcaps/OS-1-64_1024x10_fw20.pcap", "ouster-pcaps/OS-1-64_sensor_config_reduced.json"},
    {"ouster-pcaps/OS-2-128-U1_v2.3.0_1024x10.pcap", "ouster-pcaps/OS-2-128-U1_v2.3.0_1024x10.json"},
    {"ouster-pcaps/OS-2-32-U0_v2.0.0_1024x10.pcap", "ouster-pcaps/OS-2-32-U0_v2.0.0_1024x10.json"},
    {"ouster-pcaps/crc_test.pcap", "ouster-pcaps/crc_test.json"},
    {"ouster-pcaps/windowed_frame1.pcap", "ouster-pcaps/windowed_frame1_0.json"},
    {"ouster-pcaps/windowed_frame2.pcap", "ouster-pcaps/windowed_frame2_0.json"},
};

std::vector<RangeImage> decodeCapture(const std::string& pcap, const std::string& metadata_path,
                                      ReturnIndex which = ReturnIndex::kFirst) {
  return io::readOusterRangeImages(pcap, loadOusterMetadata(metadata_path), which);
}

class RealCaptureRoundTrip : public ::testing::TestWithParam<Capture> {};

TEST_P(RealCaptureRoundTrip, ProjectionReturnsEveryValidPixel) {
  RIM_REQUIRE_DATA(pcap, GetParam().pcap);
  RIM_REQUIRE_DATA(metadata, GetParam().metadata);
  const std::vector<RangeImage> images = decodeCapture(pcap, metadata);
  ASSERT_FALSE(images.empty());
  std::size_t total = 0, exact = 0, lost = 0, worst_row = 0, worst_column = 0;
  for (const RangeImage& image : images) {
    const LidarModel& model = *image.model;
    for (int v = 0; v < image.rows(); ++v)
      for (int u = 0; u < image.columns(); ++u) {
        if (!image.valid(v, u)) continue;
        ++total;
        const auto pixel = model.project(model.unproject(u, v, image.at(v, u)));
        if (!pixel) {
          ++lost;
          continue;
        }
        const int row_error = std::abs(pixel->row - v);
        int column_error = std::abs(pixel->column - u);
        column_error = std::min(column_error, image.columns() - column_error);  // seam
        exact += row_error == 0 && column_error == 0;
        worst_row = std::max<std::size_t>(worst_row, row_error);
        worst_column = std::max<std::size_t>(worst_column, column_error);
      }
  }
  ASSERT_GT(total, 1000u);
  // The batched projection gives the same pixels.
  for (const RangeImage& image : images) {
    const std::vector<Eigen::Vector3f> points = image.unprojectAll();
    std::vector<ProjectedPixel> pixels(points.size());
    std::vector<uint8_t> hits(points.size());
    image.model->projectMany(points.data(), points.size(), pixels.data(), hits.data());
    std::size_t disagreements = 0;
    for (std::size_t i = 0; i < points.size(); ++i) {
      const auto single = image.model->project(points[i]);
      disagreements += bool(hits[i]) != single.has_value() ||
                       (single && (pixels[i].row != single->row || pixels[i].column != single->column));
    }
    EXPECT_EQ(disagreements, 0u);
  }
  const double exact_fraction = double(exact) / double(total);
  std::cout << "  " << GetParam().pcap << ": " << total << " valid pixels, exact "
            << 100.0 * exact_fraction << " %, worst row error " << worst_row
            << ", worst column error " << worst_column << ", lost " << lost << "\n";
  EXPECT_GE(exact_fraction, 0.999);
  EXPECT_LE(worst_row, 1u);
  EXPECT_LE(worst_column, 1u);
  EXPECT_EQ(lost, 0u);
}

INSTANTIATE_TEST_SUITE_P(AllCaptures, RealCaptureRoundTrip, ::testing::ValuesIn(kCaptures),
                         [](const ::testing::TestParamInfo<Capture>& info) {
                           std::string name = std::to_string(info.index) + "_" + info.param.pcap;
                           for (char& c : name)
                             if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                           return name;
                         });

TEST(RealCaptureRoundTrip, SecondReturnOfTheDualProfileToo) {
  RIM_REQUIRE_DATA(pcap, "ouster-pcaps/OS-0-32-U1_v2.2.0_1024x10.pcap");
  RIM_REQUIRE_DATA(metadata, "ouster-pcaps/OS-0-32-U1_v2.2.0_1024x10.json");
  const auto images = decodeCapture(pcap, metadata, ReturnIndex::kSecond);
  ASSERT_FALSE(images.empty());
  std::size_t total = 0, exact = 0;
  for (const RangeImage& image : images)
    for (int v = 0; v < image.rows(); ++v)
      for (int u = 0; u < image.columns(); ++u)
        if (image.valid(v, u)) {
          ++total;
          const auto pixel = image.model->project(image.model->unproject(u, v, image.at(v, u)));
          exact += pixel && pixel->row == v && pixel->column == u;
        }
  ASSERT_GT(total, 100u);
  EXPECT_GE(double(exact) / total, 0.999);
}

// Nearest-neighbour distances to the reference map through a k-d tree (tests
// only: the product itself never searches trees).
struct PointSet {
  const std::vector<Eigen::Vector3f>& points;
  std::size_t kdtree_get_point_count() const { return points.size(); }
  float kdtree_get_pt(std::size_t index, std::size_t dimension) const { return points[index][dimension]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const { return false; }
};
// The index type is given, not defaulted (nanoflann 1.3: size_t, 1.4: uint32_t).
using MapTreeIndex = uint32_t;
using MapTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, PointSet>, PointSet, 3, MapTreeIndex>;

TEST(RealCaptureGeometry, LbN3ScansLandOnTheReferenceMap) {
  RIM_REQUIRE_DATA(pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(metadata, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  RIM_REQUIRE_DATA(poses_path, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt");
  RIM_REQUIRE_DATA(map_path, "ouster-extra/OS-1-128_v2.3.0_1024x10_lb_n3_map-000.ply");
  const std::vector<RangeImage> images = decodeCapture(pcap, metadata);
  const std::vector<Eigen::Isometry3d> poses = io::readKittiPoses(poses_path);  // T_map_sensor
  ASSERT_EQ(images.size(), 3u);
  ASSERT_EQ(poses.size(), 3u);

  const std::vector<Eigen::Vector3f> map = io::readPlyPoints(map_path);
  PointSet map_points{map};
  MapTree tree(3, map_points, nanoflann::KDTreeSingleIndexAdaptorParams(16));
  tree.buildIndex();

  for (std::size_t frame = 0; frame < images.size(); ++frame) {
    const Eigen::Isometry3f map_from_lidar =
        (poses[frame] * images[frame].model->intrinsics().lidar_to_sensor).cast<float>();
    std::vector<float> distances;
    for (const Eigen::Vector3f& point : images[frame].unprojectAll()) {
      const Eigen::Vector3f in_map = map_from_lidar * point;
      MapTreeIndex index;
      float squared;
      tree.knnSearch(in_map.data(), 1, &index, &squared);
      distances.push_back(std::sqrt(squared));
    }
    ASSERT_GT(distances.size(), 100000u);
    std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
    const float median = distances[distances.size() / 2];
    std::cout << "  lb_n3 frame " << images[frame].frame_id << ": median distance to the map "
              << 100.0f * median << " cm over " << distances.size() << " points\n";
    EXPECT_LT(median, 0.05f);
  }
}

}  // namespace
}  // namespace range_image_mapping
