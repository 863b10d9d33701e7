#include "range_image_mapping/registration/local_model.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

namespace range_image_mapping::registration {
namespace {

constexpr uint32_t kNoRange = std::numeric_limits<uint32_t>::max();
constexpr uint32_t kNoPoint = std::numeric_limits<uint32_t>::max();
constexpr uint32_t kNoTwin = std::numeric_limits<uint32_t>::max();

// The level of stride 1, or `count` when there is none.
template <typename Levels>
std::size_t finestLevel(const Levels& levels, std::size_t count) {
  for (std::size_t l = 0; l < count; ++l)
    if (levels[l].stride == 1) return l;
  return count;
}
// Returns of one surface lie within this of its nearest one (noise, the
// spread of a pixel's footprint on slanted surfaces).
constexpr float kSurfaceThickness_m = 0.1f;
constexpr float kSurfaceThicknessShare = 0.01f;

// Positive floats order as their bit patterns.
uint32_t rangeBits(float range) {
  uint32_t bits;
  std::memcpy(&bits, &range, sizeof bits);
  return bits;
}

void keepSmallest(uint32_t& slot, uint32_t value) {
  uint32_t current = __atomic_load_n(&slot, __ATOMIC_RELAXED);
  while (value < current &&
         !__atomic_compare_exchange_n(&slot, &current, value, true, __ATOMIC_RELAXED, __ATOMIC_RELAXED)) {
  }
}

}  // namespace

LocalModel::LocalModel(LocalModelOptions options) : options_(options) {
  if (options_.keyframes < 1) throw std::invalid_argument("local model: keyframes must be at least 1");
  if (!(options_.keyframe_distance_m >= 0.0) || !(options_.keyframe_angle_rad >= 0.0) ||
      !std::isfinite(options_.keyframe_distance_m) || !std::isfinite(options_.keyframe_angle_rad))
    throw std::invalid_argument("local model: keyframe distance and angle must be finite and not negative");
}

void LocalModel::clear() { keyframes_.clear(); }

Eigen::Isometry3d LocalModel::newestPose() const {
  return keyframes_.empty() ? Eigen::Isometry3d::Identity() : keyframes_.back().odom_from_lidar;
}

bool LocalModel::wantsKeyframe(const Eigen::Isometry3d& odom_from_lidar) const {
  if (keyframes_.empty() || keyframes_.back().provisional) return true;
  const Eigen::Isometry3d from_newest = keyframes_.back().odom_from_lidar.inverse() * odom_from_lidar;
  const bool distance = options_.keyframe_distance_m > 0.0, angle = options_.keyframe_angle_rad > 0.0;
  if (!distance && !angle) return true;
  return (distance && from_newest.translation().norm() >= options_.keyframe_distance_m) ||
         (angle && Eigen::AngleAxisd(from_newest.linear()).angle() >= options_.keyframe_angle_rad);
}

void LocalModel::add(const std::vector<VertexNormalMap>& levels, const Eigen::Isometry3d& odom_from_lidar,
                     bool provisional) {
  if (!keyframes_.empty() && keyframes_.back().provisional) keyframes_.pop_back();
  if (!keyframes_.empty() && keyframes_.back().levels.size() != levels.size())
    throw std::invalid_argument("local model: a keyframe with " + std::to_string(levels.size()) +
                                " levels after ones with " + std::to_string(keyframes_.back().levels.size()));
  Keyframe keyframe;
  if (keyframes_.size() >= options_.keyframes) {  // reuse the oldest one's buffers
    keyframe = std::move(keyframes_.front());
    keyframes_.pop_front();
  }
  keyframe.odom_from_lidar = odom_from_lidar;
  keyframe.provisional = provisional;
  keyframe.levels.resize(levels.size());
  // The finest level first: the coarser ones look up their points' twins in it.
  const std::size_t finest = finestLevel(levels, levels.size());
  for (std::size_t n = 0; n < levels.size(); ++n) {
    const std::size_t l = finest < levels.size() ? (n == 0 ? finest : n - (n <= finest)) : n;
    const VertexNormalMap& map = levels[l];
    Level& level = keyframe.levels[l];
    level.stride = map.stride;
    level.points.clear();
    level.normals.clear();
    level.finest_twin.clear();
    if (l == finest) finest_number_of_pixel_.assign(map.points.size(), kNoTwin);
    const bool twins = finest < levels.size() && l != finest;
    for (std::size_t i = 0; i < map.points.size(); ++i) {
      if (!map.points[i].allFinite() || !map.normals[i].allFinite()) continue;
      if (l == finest) finest_number_of_pixel_[i] = uint32_t(level.points.size());
      if (twins) {
        // Level pixel (r, c) is full-resolution pixel (s r, s c).
        const VertexNormalMap& full = levels[finest];
        const std::size_t row = i / std::size_t(map.columns), column = i % std::size_t(map.columns);
        const std::size_t full_row = row * map.stride, full_column = column * map.stride;
        uint32_t twin = kNoTwin;
        if (full_row < std::size_t(full.rows) && full_column < std::size_t(full.columns)) {
          twin = finest_number_of_pixel_[full_row * full.columns + full_column];
          // Only the very same point (coordinates to the bit) shares a projection.
          if (twin != kNoTwin && !(keyframe.levels[finest].points[twin] == map.points[i])) twin = kNoTwin;
        }
        level.finest_twin.push_back(twin);
      }
      level.points.push_back(map.points[i]);
      level.normals.push_back(map.normals[i]);
    }
  }
  keyframes_.push_back(std::move(keyframe));
}

void LocalModel::render(const LidarModel& model, const Eigen::Isometry3d& odom_from_view,
                        std::vector<VertexNormalMap>& levels) const {
  const std::size_t level_count = keyframes_.empty() ? 0 : keyframes_.back().levels.size();
  levels.resize(level_count);
  nearest_.resize(level_count);
  winner_.resize(level_count);
  const Eigen::Isometry3d view_from_odom = odom_from_view.inverse();
  view_from_keyframe_.resize(keyframes_.size());
  // Keyframes newest first, so that ties go to the newer one.
  for (std::size_t k = 0; k < keyframes_.size(); ++k)
    view_from_keyframe_[k] = (view_from_odom * keyframes_[keyframes_.size() - 1 - k].odom_from_lidar).cast<float>();
  const auto keyframe = [&](std::size_t k) -> const Keyframe& { return keyframes_[keyframes_.size() - 1 - k]; };
  constexpr std::size_t kChunk = 2048;
  // The finest level first: its projections serve the coarser levels' twins.
  const std::size_t finest = keyframes_.empty() ? 0 : finestLevel(keyframes_.back().levels, level_count);
  finest_pixels_.resize(keyframes_.size());
  finest_hits_.resize(keyframes_.size());
  level_pixels_.resize(keyframes_.size());
  level_hits_.resize(keyframes_.size());
  for (std::size_t n = 0; n < level_count; ++n) {
    const std::size_t l = finest < level_count ? (n == 0 ? finest : n - (n <= finest)) : n;
    const bool twins = finest < level_count && l != finest;
    const int s = keyframes_.back().levels[l].stride;
    VertexNormalMap& level = levels[l];
    level.stride = s;
    level.rows = (model.rows() + s - 1) / s;
    level.columns = (model.columns() + s - 1) / s;
    const std::size_t size = std::size_t(level.rows) * level.columns;
    std::vector<uint32_t>& nearest = nearest_[l];
    std::vector<uint32_t>& winner = winner_[l];
    nearest.assign(size, kNoRange);
    winner.assign(size, kNoPoint);
    first_point_.assign(keyframes_.size() + 1, 0);
    for (std::size_t k = 0; k < keyframes_.size(); ++k)
      first_point_[k + 1] = first_point_[k] + keyframe(k).levels[l].points.size();
    if (first_point_.back() >= kNoPoint) throw std::length_error("local model: too many points to render");
    pixel_of_point_.resize(first_point_.back());
    range_of_point_.resize(first_point_.back());
    pixel_tables_.build(level, model.rows(), model.columns());
    // The keyframes' points of this level in the same order (a deque's
    // indexing costs more than the transform in the per-pixel loop below).
    level_points_.resize(keyframes_.size());
    for (std::size_t k = 0; k < keyframes_.size(); ++k) level_points_[k] = &keyframe(k).levels[l];

    // Pass 1: every point's pixel and range, and each pixel's nearest range.
    // A coarser level's point with a twin in the finest level takes the
    // twin's projection (the same point, the same pixel) instead of its own.
    for (std::size_t k = 0; k < keyframes_.size(); ++k) {
      const Level& points = keyframe(k).levels[l];
      const bool has_twins = twins && points.finest_twin.size() == points.points.size();
      const Eigen::Isometry3f& view_from_keyframe = view_from_keyframe_[k];
      const std::size_t first = first_point_[k];
      std::vector<ProjectedPixel>& pixels = l == finest ? finest_pixels_[k] : level_pixels_[k];
      std::vector<uint8_t>& hits = l == finest ? finest_hits_[k] : level_hits_[k];
      pixels.resize(points.points.size());
      hits.resize(points.points.size());
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.points.size(), kChunk),
                        [&](const tbb::blocked_range<std::size_t>& block) {
                          Eigen::Vector3f moved[kChunk];
                          const std::size_t n = block.size(), begin = block.begin();
                          if (!has_twins) {
                            for (std::size_t i = 0; i < n; ++i) moved[i] = view_from_keyframe * points.points[begin + i];
                            model.projectMany(moved, n, &pixels[begin], &hits[begin]);
                          } else {
                            std::size_t own[kChunk], count = 0;
                            for (std::size_t i = begin; i < block.end(); ++i) {
                              const uint32_t twin = points.finest_twin[i];
                              if (twin != kNoTwin) {
                                pixels[i] = finest_pixels_[k][twin];
                                hits[i] = finest_hits_[k][twin];
                              } else {
                                moved[count] = view_from_keyframe * points.points[i];
                                own[count++] = i;
                              }
                            }
                            ProjectedPixel projected[kChunk];
                            uint8_t projected_hits[kChunk];
                            if (count > 0) model.projectMany(moved, count, projected, projected_hits);
                            for (std::size_t j = 0; j < count; ++j) {
                              pixels[own[j]] = projected[j];
                              hits[own[j]] = projected_hits[j];
                            }
                          }
                          for (std::size_t i = begin; i < block.end(); ++i) {
                            const std::size_t number = first + i;
                            if (!hits[i]) {
                              pixel_of_point_[number] = kNoPoint;
                              continue;
                            }
                            const uint32_t pixel = uint32_t(pixel_tables_.index(pixels[i]));
                            pixel_of_point_[number] = pixel;
                            range_of_point_[number] = pixels[i].range;
                            keepSmallest(nearest[pixel], rangeBits(pixels[i].range));
                          }
                        });
    }
    // Pass 2: of the points on the nearest surface, the newest keyframe's.
    // The nearest point itself would be biased towards the sensor by the
    // noise: the least of several noisy ranges of one surface.
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, first_point_.back(), 8192),
                      [&](const tbb::blocked_range<std::size_t>& block) {
                        for (std::size_t number = block.begin(); number < block.end(); ++number) {
                          const uint32_t pixel = pixel_of_point_[number];
                          if (pixel == kNoPoint) continue;
                          const float range = range_of_point_[number];
                          float front;
                          const uint32_t bits = __atomic_load_n(&nearest[pixel], __ATOMIC_RELAXED);
                          std::memcpy(&front, &bits, sizeof front);
                          if (range <= front + std::max(kSurfaceThickness_m, kSurfaceThicknessShare * front))
                            keepSmallest(winner[pixel], uint32_t(number));
                        }
                      });

    // Each pixel's winner, moved into the view.
    level.points.resize(size);
    level.normals.resize(size);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, size, 4096), [&](const tbb::blocked_range<std::size_t>& block) {
      constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
      for (std::size_t p = block.begin(); p < block.end(); ++p) {
        const uint32_t number = winner[p];
        if (number == kNoPoint) {
          level.points[p] = level.normals[p] = Eigen::Vector3f::Constant(kNaN);
          continue;
        }
        std::size_t k = 0;
        while (number >= first_point_[k + 1]) ++k;
        const Level& points = *level_points_[k];
        const std::size_t i = number - first_point_[k];
        level.points[p] = view_from_keyframe_[k] * points.points[i];
        level.normals[p] = view_from_keyframe_[k].linear() * points.normals[i];
      }
    });
  }
}

}  // namespace range_image_mapping::registration
