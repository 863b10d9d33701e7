#include "range_image_mapping/io/png.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>

namespace range_image_mapping::io {
namespace {

std::string temporaryPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("rim_png_test_" + name)).string();
}

TEST(GreyPng, EightBitRoundTrip) {
  const int width = 37, height = 11;
  std::vector<uint8_t> pixels(width * height);
  for (std::size_t i = 0; i < pixels.size(); ++i) pixels[i] = static_cast<uint8_t>(i * 13 + i / 7);
  const std::string path = temporaryPath("grey8.png");
  writeGrey8Png(path, width, height, pixels);
  const GreyPng read = readGreyPng(path);
  EXPECT_EQ(read.width, width);
  EXPECT_EQ(read.height, height);
  EXPECT_EQ(read.bit_depth, 8);
  EXPECT_EQ(read.pixels, std::vector<uint16_t>(pixels.begin(), pixels.end()));
  std::remove(path.c_str());
}

TEST(GreyPng, SixteenBitRoundTrip) {
  const int width = 64, height = 5;
  std::vector<uint16_t> pixels(width * height);
  for (std::size_t i = 0; i < pixels.size(); ++i) pixels[i] = static_cast<uint16_t>(i * 977 + 1);
  pixels[3] = 0xff00;  // the byte order matters
  const std::string path = temporaryPath("grey16.png");
  writeGrey16Png(path, width, height, pixels);
  const GreyPng read = readGreyPng(path);
  EXPECT_EQ(read.bit_depth, 16);
  EXPECT_EQ(read.width, width);
  EXPECT_EQ(read.height, height);
  EXPECT_EQ(read.pixels, pixels);
  std::remove(path.c_str());
}

TEST(GreyPng, ClearErrors) {
  const std::string path = temporaryPath("bad.png");
  EXPECT_THROW(writeGrey8Png(path, 4, 4, std::vector<uint8_t>(15)), std::invalid_argument);
  EXPECT_THROW(writeGrey8Png(path, 0, 4, {}), std::invalid_argument);
  EXPECT_THROW(writeGrey8Png("/nonexistent/dir/a.png", 1, 1, {0}), PngError);
  EXPECT_THROW(readGreyPng("/nonexistent/a.png"), PngError);
  std::ofstream(path, std::ios::binary) << "not a png at all";
  try {
    readGreyPng(path);
    ADD_FAILURE() << "expected PngError";
  } catch (const PngError& error) {
    EXPECT_NE(std::string(error.what()).find("is not a PNG file"), std::string::npos)
        << error.what();
  }
  // A valid PNG cut short fails inside libpng and comes back as PngError.
  writeGrey8Png(path, 100, 100, std::vector<uint8_t>(10000, 7));
  std::filesystem::resize_file(path, 60);
  EXPECT_THROW(readGreyPng(path), PngError);
  std::remove(path.c_str());
}

TEST(RangeImagePng, DestaggeredLogarithmicGrey) {
  LidarIntrinsics intrinsics = LidarIntrinsics::synthetic(4, 16, 0.1, -0.1);
  intrinsics.pixel_shift_by_row = {3, 2, 1, 0};
  RangeImage image(std::make_shared<const LidarModel>(intrinsics));
  image.range[image.index(0, 0)] = 0.5f;     // nearer than near_m: white
  image.range[image.index(1, 5)] = 10.0f;    // halfway in log between 1 m and 100 m
  image.range[image.index(2, 15)] = 100.0f;  // far_m: darkest valid grey
  image.range[image.index(3, 7)] = 1000.0f;  // beyond far_m: clamped
  image.range[image.index(3, 8)] = 0.0f;     // not a return
  const std::string path = temporaryPath("range.png");
  RangePngOptions options;
  options.row_repeat = 2;
  writeRangeImagePng(path, image, options);
  const GreyPng read = readGreyPng(path);
  ASSERT_EQ(read.width, 16);
  ASSERT_EQ(read.height, 8);
  ASSERT_EQ(read.bit_depth, 8);
  const auto grey = [&](int row, int column) { return read.pixels[row * 16 + column]; };
  // Staggered (v, u) shows at column (u + shift[v]) mod W, each row twice.
  EXPECT_EQ(grey(0, 3), 255);
  EXPECT_EQ(grey(1, 3), 255);
  EXPECT_EQ(grey(2, 7), 1 + 127);
  EXPECT_EQ(grey(4, 0), 1);
  EXPECT_EQ(grey(6, 7), 1);
  int lit = 0;
  for (const uint16_t value : read.pixels) lit += value != 0;
  EXPECT_EQ(lit, 8);  // four returns, each on two rows; the rest black
  EXPECT_THROW(writeRangeImagePng(path, RangeImage()), std::invalid_argument);
  options.far_m = 0.5f;
  EXPECT_THROW(writeRangeImagePng(path, image, options), std::invalid_argument);
  std::remove(path.c_str());
}

}  // namespace
}  // namespace range_image_mapping::io
