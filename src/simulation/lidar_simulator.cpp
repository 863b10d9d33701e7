#include "range_image_mapping/simulation/lidar_simulator.h"

#include "seeded_random.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>

namespace range_image_mapping::simulation {
namespace {

constexpr double kMaxRangeMillimetres = (1 << 19) - 1;  // the narrowest range field (RNG19)
constexpr uint64_t kLegacyEncoderTicksPerRevolution = 90112;
constexpr int kFootprintRing = 4;  // sub-rays around the centre ray with divergence
constexpr double kNoiseReach = 6.0;  // rays reach max range plus this many sigmas
constexpr double kLambertianReflectivity = 50.0;  // grey world, albedo 50 %
constexpr double kSignalAtOneMetre = 100.0;        // photons per reflectivity unit at 1 m

void requireWithin(double value, double low, double high, const std::string& field) {
  if (!(std::isfinite(value) && value >= low && value <= high)) {
    std::ostringstream message;
    message << "LidarSimulator: " << field << " must be within [" << low << ", " << high
            << "], got " << value;
    throw std::invalid_argument(message.str());
  }
}

void validateEffects(const SensorEffects& effects) {
  requireWithin(effects.range_noise_sigma_m, 0.0, 10.0, "range_noise_sigma_m");
  requireWithin(effects.dropout_probability, 0.0, 1.0, "dropout_probability");
  requireWithin(effects.min_range_m, 0.0, kMaxRangeMillimetres / 1000.0, "min_range_m");
  requireWithin(effects.max_range_m, 0.0, kMaxRangeMillimetres / 1000.0, "max_range_m");
  if (!(effects.max_range_m > effects.min_range_m))
    throw std::invalid_argument("LidarSimulator: max_range_m must be above min_range_m");
  requireWithin(effects.beam_divergence_rad, 0.0, 0.1, "beam_divergence_rad");
}

}  // namespace

// Per-thread scratch for one column's rays (sized once, reused every frame).
struct LidarSimulator::ColumnBuffers {
  std::vector<Eigen::Vector3f> origins, directions, normals;
  std::vector<float> distances;
  std::vector<int> actors;  // per ray: the actor hit, -1 for the scene or nothing
  ActorSnapshot snapshot;   // the actors at the column's time
  void resize(std::size_t rays) {
    origins.resize(rays);
    directions.resize(rays);
    normals.resize(rays);
    distances.resize(rays);
    actors.resize(rays);
  }
};

void LidarSimulator::setActors(const std::vector<MovingActor>* actors) {
  if (actors && actors->size() >= 65535)
    throw std::invalid_argument("LidarSimulator: at most 65534 actors (16-bit labels), got " +
                                std::to_string(actors->size()));
  actors_ = actors && !actors->empty() ? actors : nullptr;
}

LidarSimulator::LidarSimulator(LidarModelConstPtr model, const RayCaster& caster,
                               SensorEffects effects, uint32_t seed, double frequency_hz)
    : model_(std::move(model)),
      caster_(caster),
      effects_(effects),
      seed_(seed),
      frequency_hz_(frequency_hz) {
  if (!model_) throw std::invalid_argument("LidarSimulator: no sensor model");
  validateEffects(effects_);
  requireWithin(frequency_hz_, 1e-3, 1000.0, "frequency_hz");
  rows_ = model_->rows();
  columns_ = model_->columns();
  const LidarIntrinsics& intrinsics = model_->intrinsics();
  beam_origin_norm_ =
      static_cast<float>(std::hypot(intrinsics.beam_origin_radius_m, intrinsics.beam_origin_z_m));
  footprint_.push_back(Eigen::Vector3d::UnitZ());
  if (effects_.beam_divergence_rad > 0.0) {
    const double half_angle = 0.5 * effects_.beam_divergence_rad;
    for (int k = 0; k < kFootprintRing; ++k) {
      const double angle = 2.0 * M_PI * k / kFootprintRing;
      footprint_.emplace_back(std::sin(half_angle) * std::cos(angle),
                              std::sin(half_angle) * std::sin(angle), std::cos(half_angle));
    }
  }
}

SimulatedScan LidarSimulator::simulate(const Trajectory& trajectory, double start_time_s,
                                       uint32_t frame_id) const {
  SimulatedScan scan;
  simulate(trajectory, start_time_s, frame_id, scan);
  return scan;
}

void LidarSimulator::simulate(const Trajectory& trajectory, double start_time_s, uint32_t frame_id,
                              SimulatedScan& scan) const {
  if (!(std::isfinite(start_time_s) && start_time_s >= 0.0))
    throw std::invalid_argument("LidarSimulator: start_time_s must be finite and >= 0 (sensor "
                                "timestamps are unsigned nanoseconds), got " +
                                std::to_string(start_time_s));
  const double last_time =
      effects_.motion_distortion ? columnTime(start_time_s, columns_ - 1) : start_time_s;
  if (start_time_s < trajectory.startTime() || last_time > trajectory.endTime()) {
    std::ostringstream message;
    message.precision(12);
    message << "LidarSimulator: the scan needs poses for [" << start_time_s << ", " << last_time
            << "] s, the trajectory covers [" << trajectory.startTime() << ", "
            << trajectory.endTime() << "] s";
    throw std::out_of_range(message.str());
  }

  // Reused when it has exactly the fields written below (single return, with signal).
  const std::size_t pixels = static_cast<std::size_t>(rows_) * columns_;
  const LidarScan& raw = scan.raw;
  if (raw.rows != rows_ || raw.columns != columns_ || raw.range.size() != pixels ||
      raw.reflectivity.size() != pixels || raw.signal.size() != pixels ||
      raw.near_ir.size() != pixels || !raw.range2.empty() ||
      raw.timestamp_ns.size() != static_cast<std::size_t>(columns_))
    scan.raw = LidarScan(rows_, columns_, UdpProfile::kLegacy);
  scan.raw.frame_id = frame_id;
  scan.start_time_s = start_time_s;
  scan.column_poses.resize(columns_);
  scan.true_range.resize(pixels);
  scan.true_actor.resize(pixels);
  const Eigen::Isometry3d start_pose =
      effects_.motion_distortion ? Eigen::Isometry3d::Identity() : trajectory.pose(start_time_s);

  // Every column writes only its own pixels, and its noise depends only on
  // (seed, frame, column): any split over threads gives the same scan.
  tbb::parallel_for(tbb::blocked_range<int>(0, columns_, 8), [&](const tbb::blocked_range<int>& range) {
    thread_local ColumnBuffers buffers;
    for (int u = range.begin(); u != range.end(); ++u) {
      const Eigen::Isometry3d pose = effects_.motion_distortion
                                         ? trajectory.pose(columnTime(start_time_s, u))
                                         : start_pose;
      scan.column_poses[u] = pose;
      simulateColumn(u, pose, frame_id, scan, buffers);
    }
  });
  toRangeImage(scan.raw, model_, ReturnIndex::kFirst, scan.image);
}

void LidarSimulator::simulateColumn(int u, const Eigen::Isometry3d& pose, uint32_t frame_id,
                                    SimulatedScan& scan, ColumnBuffers& buffers) const {
  LidarScan& raw = scan.raw;
  const double time_s = columnTime(scan.start_time_s, u);
  raw.timestamp_ns[u] = static_cast<uint64_t>(std::llround(time_s * 1e9));
  raw.measurement_id[u] = static_cast<uint16_t>(u);
  raw.encoder_count[u] = static_cast<uint32_t>(u * kLegacyEncoderTicksPerRevolution / columns_);
  const bool in_window = model_->intrinsics().columnInWindow(u);
  raw.status[u] = in_window ? 1u : 0u;

  const std::size_t sub_rays = footprint_.size();
  if (in_window) {
    buffers.resize(rows_ * sub_rays);
    const Eigen::Matrix3d rotation = pose.linear();
    for (int v = 0; v < rows_; ++v) {
      const Eigen::Vector3f& direction = model_->direction(u, v);
      // Pi^-1 is p = r d + o: range n is the beam origin, where the ray starts.
      const Eigen::Vector3f beam_start = model_->offset(u, v) + beam_origin_norm_ * direction;
      const Eigen::Vector3f origin = (pose * beam_start.cast<double>()).cast<float>();
      const Eigen::Vector3d beam = (rotation * direction.cast<double>()).normalized();
      Eigen::Matrix3d beam_frame;  // columns: two directions across the beam, the beam
      if (sub_rays > 1) {
        const Eigen::Vector3d helper =
            std::abs(beam.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
        const Eigen::Vector3d across = beam.cross(helper).normalized();
        beam_frame << across, beam.cross(across), beam;
      }
      for (std::size_t k = 0; k < sub_rays; ++k) {
        buffers.origins[v * sub_rays + k] = origin;
        buffers.directions[v * sub_rays + k] =
            (k == 0 ? beam : (beam_frame * footprint_[k]).normalized()).cast<float>();
      }
    }
    const float reach = static_cast<float>(effects_.max_range_m +
                                           kNoiseReach * effects_.range_noise_sigma_m -
                                           beam_origin_norm_);
    caster_.cast(buffers.origins.data(), buffers.directions.data(), rows_ * sub_rays, 0.0f,
                 std::max(reach, 0.0f), buffers.distances.data(), buffers.normals.data());
    std::fill(buffers.actors.begin(), buffers.actors.end(), -1);
    if (actors_) castActors(effects_.motion_distortion ? time_s : scan.start_time_s, std::max(reach, 0.0f),
                            buffers);
  }

  SeededRandom random({seed_, frame_id, static_cast<uint64_t>(u)});
  const bool noisy = effects_.range_noise_sigma_m > 0.0;
  const bool dropping = effects_.dropout_probability > 0.0;
  const double n = beam_origin_norm_;
  for (int v = 0; v < rows_; ++v) {
    const std::size_t pixel = static_cast<std::size_t>(v) * columns_ + u;
    raw.range[pixel] = 0;
    raw.reflectivity[pixel] = 0;
    raw.signal[pixel] = 0;
    raw.near_ir[pixel] = 0;
    scan.true_range[pixel] = std::numeric_limits<float>::quiet_NaN();
    scan.true_actor[pixel] = 0;
    if (!in_window) continue;
    // Drawn for every pixel, hit or not: one pixel's draws never shift another's.
    const double noise = noisy ? effects_.range_noise_sigma_m * random.gaussian() : 0.0;
    const bool dropped = dropping && random.uniform() < effects_.dropout_probability;

    const std::size_t first_ray = v * sub_rays;
    if (!std::isnan(buffers.distances[first_ray])) {
      scan.true_range[pixel] = static_cast<float>(n + buffers.distances[first_ray]);
      scan.true_actor[pixel] = static_cast<uint16_t>(buffers.actors[first_ray] + 1);
    }
    std::size_t nearest = first_ray;
    for (std::size_t k = 1; k < sub_rays; ++k) {
      const float distance = buffers.distances[first_ray + k];
      if (!std::isnan(distance) && !(distance >= buffers.distances[nearest])) nearest = first_ray + k;
    }
    const float distance = buffers.distances[nearest];
    if (std::isnan(distance) || dropped) continue;
    const double measured = n + distance + noise;
    if (measured < effects_.min_range_m || measured > effects_.max_range_m) continue;
    const long long millimetres = std::llround(measured * 1000.0);
    if (millimetres <= 0) continue;
    raw.range[pixel] = static_cast<uint32_t>(millimetres);
    // Both positive: + 0.5 and truncation round them without a libm call.
    const double incidence = std::abs(buffers.directions[nearest].dot(buffers.normals[nearest]));
    const int reflectivity = static_cast<int>(kLambertianReflectivity * std::min(incidence, 1.0) + 0.5);
    raw.reflectivity[pixel] = static_cast<uint8_t>(reflectivity);
    const double signal = reflectivity * kSignalAtOneMetre / (measured * measured);
    raw.signal[pixel] = static_cast<uint16_t>(std::clamp(signal + 0.5, 1.0, 65535.0));
  }
}

// The actors at the column's time against every ray of the column: an actor
// nearer than the scene's hit replaces it (distance and normal), exactly as a
// mesh of the boxes in the same Embree scene would, without rebuilding one
// per column.
void LidarSimulator::castActors(double time_s, float reach_m, ColumnBuffers& buffers) const {
  buffers.snapshot.reset(*actors_, time_s);
  for (std::size_t ray = 0; ray < buffers.distances.size(); ++ray) {
    const float scene_distance = buffers.distances[ray];
    const double far = std::isnan(scene_distance) ? reach_m : scene_distance;
    const ActorHit hit = buffers.snapshot.intersect(buffers.origins[ray].cast<double>(),
                                                    buffers.directions[ray].cast<double>(), 0.0, far);
    if (hit.actor < 0) continue;
    buffers.distances[ray] = static_cast<float>(hit.distance_m);
    buffers.normals[ray] = hit.normal_world.cast<float>();
    buffers.actors[ray] = hit.actor;
  }
}

}  // namespace range_image_mapping::simulation
