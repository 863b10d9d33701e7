#include "range_image_mapping/io/png.h"

#include <png.h>

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>

namespace range_image_mapping::io {
namespace {

// libpng reports errors by longjmp; the handler keeps the message so the
// setjmp branch can turn it into an exception once no libpng frame is live.
struct ErrorMessage {
  char text[256] = "unknown libpng error";
};

void onPngError(png_structp png, png_const_charp message) {
  auto* error = static_cast<ErrorMessage*>(png_get_error_ptr(png));
  std::snprintf(error->text, sizeof(error->text), "%s", message);
  png_longjmp(png, 1);
}

void onPngWarning(png_structp, png_const_charp) {}

// Closes the FILE on every path, including the exception ones.
struct FileCloser {
  std::FILE* file = nullptr;
  ~FileCloser() {
    if (file) std::fclose(file);
  }
};

// libpng's part of writing, alone in its frame: after a longjmp back to the
// setjmp here nothing but the return value is used.
bool writeRows(png_structp png, png_infop info, std::FILE* file, int width, int height,
               const uint8_t* pixels, int bit_depth) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_init_io(png, file);
  png_set_IHDR(png, info, width, height, bit_depth, PNG_COLOR_TYPE_GRAY, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  if (bit_depth == 16) png_set_swap(png);  // PNG stores 16-bit samples big-endian
  const std::size_t row_bytes = static_cast<std::size_t>(width) * (bit_depth / 8);
  for (int row = 0; row < height; ++row)
    png_write_row(png, const_cast<png_bytep>(pixels + row * row_bytes));
  png_write_end(png, nullptr);
  return true;
}

// 16-bit pixels are host (little-endian) uint16s.
void writeGreyPng(const std::string& path, int width, int height, const uint8_t* pixels,
                  std::size_t pixel_count, int bit_depth) {
  if (width <= 0 || height <= 0)
    throw std::invalid_argument("PNG: " + path + ": size must be positive, got " +
                                std::to_string(width) + " x " + std::to_string(height));
  if (pixel_count != static_cast<std::size_t>(width) * height)
    throw std::invalid_argument("PNG: " + path + ": " + std::to_string(pixel_count) +
                                " pixels for " + std::to_string(width) + " x " +
                                std::to_string(height));
  FileCloser closer{std::fopen(path.c_str(), "wb")};
  if (!closer.file) throw PngError("PNG: cannot write " + path);

  ErrorMessage error;
  png_structp png =
      png_create_write_struct(PNG_LIBPNG_VER_STRING, &error, onPngError, onPngWarning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  const bool written =
      png && info && writeRows(png, info, closer.file, width, height, pixels, bit_depth);
  png_destroy_write_struct(&png, &info);
  if (!written) throw PngError("PNG: writing " + path + " failed: " + error.text);
  if (std::fflush(closer.file) != 0) throw PngError("PNG: writing " + path + " failed");
}

// libpng's part of reading (see writeRows); the results go to *image, which
// lives in the caller's frame. Leaves image->pixels empty for formats other
// than non-interlaced 8 or 16-bit grey.
bool readRows(png_structp png, png_infop info, std::FILE* file, std::size_t signature_bytes,
              GreyPng* image, std::vector<png_byte>* row_buffer) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_init_io(png, file);
  png_set_sig_bytes(png, static_cast<int>(signature_bytes));
  png_read_info(png, info);
  image->bit_depth = png_get_bit_depth(png, info);
  image->width = static_cast<int>(png_get_image_width(png, info));
  image->height = static_cast<int>(png_get_image_height(png, info));
  if (png_get_color_type(png, info) != PNG_COLOR_TYPE_GRAY ||
      (image->bit_depth != 8 && image->bit_depth != 16) ||
      png_get_interlace_type(png, info) != PNG_INTERLACE_NONE)
    return true;
  if (image->bit_depth == 16) png_set_swap(png);
  png_read_update_info(png, info);
  row_buffer->resize(png_get_rowbytes(png, info));
  image->pixels.resize(static_cast<std::size_t>(image->width) * image->height);
  for (int row = 0; row < image->height; ++row) {
    png_read_row(png, row_buffer->data(), nullptr);
    uint16_t* out = image->pixels.data() + static_cast<std::size_t>(row) * image->width;
    if (image->bit_depth == 8) {
      std::copy(row_buffer->begin(), row_buffer->begin() + image->width, out);
    } else {
      std::memcpy(out, row_buffer->data(),
                  static_cast<std::size_t>(image->width) * sizeof(uint16_t));
    }
  }
  png_read_end(png, nullptr);
  return true;
}

}  // namespace

void writeGrey8Png(const std::string& path, int width, int height,
                   const std::vector<uint8_t>& pixels) {
  writeGreyPng(path, width, height, pixels.data(), pixels.size(), 8);
}

void writeGrey16Png(const std::string& path, int width, int height,
                    const std::vector<uint16_t>& pixels) {
  writeGreyPng(path, width, height, reinterpret_cast<const uint8_t*>(pixels.data()), pixels.size(),
               16);
}

GreyPng readGreyPng(const std::string& path) {
  FileCloser closer{std::fopen(path.c_str(), "rb")};
  if (!closer.file) throw PngError("PNG: cannot open " + path);
  png_byte signature[8] = {};
  if (std::fread(signature, 1, sizeof(signature), closer.file) != sizeof(signature) ||
      png_sig_cmp(signature, 0, sizeof(signature)) != 0)
    throw PngError("PNG: " + path + " is not a PNG file");

  ErrorMessage error;
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &error, onPngError, onPngWarning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  GreyPng image;
  std::vector<png_byte> row_buffer;
  const bool read =
      png && info && readRows(png, info, closer.file, sizeof(signature), &image, &row_buffer);
  png_destroy_read_struct(&png, &info, nullptr);
  if (!read) throw PngError("PNG: reading " + path + " failed: " + error.text);
  if (image.pixels.empty())
    throw PngError("PNG: " + path + " is not a non-interlaced 8 or 16-bit grey image");
  return image;
}

void writeRangeImagePng(const std::string& path, const RangeImage& image,
                        const RangePngOptions& options) {
  if (!image.model)
    throw std::invalid_argument("writeRangeImagePng: the image has no sensor model");
  if (!(options.near_m > 0.0f) || !(options.far_m > options.near_m))
    throw std::invalid_argument("writeRangeImagePng: need 0 < near_m < far_m");
  if (options.row_repeat < 1)
    throw std::invalid_argument("writeRangeImagePng: row_repeat must be at least 1");
  const RangeImage display = image.destaggered();
  const int rows = display.rows();
  const int columns = display.columns();
  const float log_near = std::log(options.near_m);
  const float log_span = std::log(options.far_m) - log_near;
  std::vector<uint8_t> pixels(static_cast<std::size_t>(rows) * options.row_repeat * columns, 0);
  for (int v = 0; v < rows; ++v) {
    uint8_t* first_copy =
        pixels.data() + static_cast<std::size_t>(v) * options.row_repeat * columns;
    for (int u = 0; u < columns; ++u) {
      const float range = display.at(v, u);
      if (!isValidRange(range)) continue;
      const float nearness = 1.0f - (std::log(range) - log_near) / log_span;
      first_copy[u] =
          static_cast<uint8_t>(1 + std::lround(254.0f * std::clamp(nearness, 0.0f, 1.0f)));
    }
    for (int copy = 1; copy < options.row_repeat; ++copy)
      std::copy(first_copy, first_copy + columns,
                first_copy + static_cast<std::size_t>(copy) * columns);
  }
  writeGrey8Png(path, columns, rows * options.row_repeat, pixels);
}

}  // namespace range_image_mapping::io
