#include "range_image_mapping/evaluation/actor_trail.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <cmath>
#include <stdexcept>
#include <unordered_map>

namespace range_image_mapping::evaluation {
namespace {

constexpr double kCellM = 2.0;  // of the horizontal grid the swept boxes are filed in

// One actor box at one tracked pose, grown as the options say.
struct SweptBox {
  Eigen::Isometry3d box_from_world;  // the actor frame, moved to the box's centre
  Eigen::Vector3d half_size_m;
  Eigen::Vector3d centre_shift_m;    // of the grown box, in the box frame (the raised bottom, the grown top)
  int kind;
};

int64_t cellKey(int64_t x, int64_t y) { return (x << 32) ^ (y & 0xffffffff); }

}  // namespace

ActorTrail measureActorTrail(const std::vector<Eigen::Vector3f>& points, const std::vector<io::ActorTrack>& tracks,
                             const ActorTrailOptions& options) {
  const double margin = options.margin_m;
  if (!(std::isfinite(margin) && margin >= 0.0))
    throw std::invalid_argument("measureActorTrail: margin_m must be finite and >= 0");
  ActorTrail trail;
  trail.points = points.size();
  std::vector<SweptBox> boxes;
  std::unordered_map<int64_t, std::vector<uint32_t>> cells;
  for (const io::ActorTrack& track : tracks) {
    int kind = -1;
    for (std::size_t k = 0; k < trail.by_kind.size(); ++k)
      if (trail.by_kind[k].kind == track.kind) kind = static_cast<int>(k);
    if (kind < 0) {
      kind = static_cast<int>(trail.by_kind.size());
      trail.by_kind.push_back({track.kind, 0});
    }
    for (std::size_t f = 0; f < track.world_from_actor.size(); ++f) {
      // A standing actor repeats its pose: file it once.
      if (f > 0 && track.world_from_actor[f].isApprox(track.world_from_actor[f - 1], 1e-12)) continue;
      for (const io::ActorTrackBox& box : track.boxes) {
        SweptBox swept;
        // Sideways and up by the margin, the bottom raised by it: the half
        // height stays, the centre moves up by the margin.
        swept.half_size_m = box.half_size_m + Eigen::Vector3d(margin, margin, 0.0);
        swept.centre_shift_m = Eigen::Vector3d(0.0, 0.0, margin);
        Eigen::Isometry3d world_from_box = track.world_from_actor[f];
        world_from_box.translate(box.centre_m);
        swept.box_from_world = world_from_box.inverse();
        swept.kind = kind;
        // File it in every cell its horizontal bounds touch.
        const double reach = swept.half_size_m.head<2>().norm();
        const Eigen::Vector3d centre = world_from_box.translation();
        const auto index = static_cast<uint32_t>(boxes.size());
        boxes.push_back(swept);
        for (int64_t x = int64_t(std::floor((centre.x() - reach) / kCellM));
             x <= int64_t(std::floor((centre.x() + reach) / kCellM)); ++x)
          for (int64_t y = int64_t(std::floor((centre.y() - reach) / kCellM));
               y <= int64_t(std::floor((centre.y() + reach) / kCellM)); ++y)
            cells[cellKey(x, y)].push_back(index);
      }
    }
  }

  using Counts = std::vector<std::size_t>;  // per kind
  const Counts counts = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, points.size(), 4096), Counts(trail.by_kind.size(), 0),
      [&](const tbb::blocked_range<std::size_t>& range, Counts counts) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
          const Eigen::Vector3d point = points[i].cast<double>();
          const auto found = cells.find(cellKey(int64_t(std::floor(point.x() / kCellM)),
                                                int64_t(std::floor(point.y() / kCellM))));
          if (found == cells.end()) continue;
          for (const uint32_t index : found->second) {
            const SweptBox& box = boxes[index];
            const Eigen::Vector3d local = box.box_from_world * point - box.centre_shift_m;
            if (((local.cwiseAbs() - box.half_size_m).array() <= 0.0).all()) {
              ++counts[box.kind];
              break;
            }
          }
        }
        return counts;
      },
      [](Counts a, const Counts& b) {
        for (std::size_t k = 0; k < a.size(); ++k) a[k] += b[k];
        return a;
      });
  for (std::size_t k = 0; k < counts.size(); ++k) {
    trail.by_kind[k].points_inside = counts[k];
    trail.points_inside += counts[k];
  }
  trail.share = trail.points ? double(trail.points_inside) / trail.points : 0.0;
  return trail;
}

}  // namespace range_image_mapping::evaluation
