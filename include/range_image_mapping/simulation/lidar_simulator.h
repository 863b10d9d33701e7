// A spinning LiDAR in a mesh scene: every column is cast from the pose at its
// own timestamp (motion distortion), with the sensor's exact beam tables.
#pragma once

#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/simulation/moving_actors.h"
#include "range_image_mapping/simulation/ray_caster.h"
#include "range_image_mapping/simulation/trajectory.h"

#include <cstdint>
#include <vector>

namespace range_image_mapping::simulation {

// Checked when the simulator is built (std::invalid_argument naming the field).
struct SensorEffects {
  double range_noise_sigma_m = 0.0;  // Gaussian, on the range; >= 0
  double dropout_probability = 0.0;  // a return lost at random; within [0, 1]
  double min_range_m = 0.3;          // closer returns are lost (the beam is still blocked)
  double max_range_m = 120.0;        // within (min_range_m, 524.287] (19-bit millimetres)
  double beam_divergence_rad = 0.0;  // > 0: nearest of a few rays spread over the footprint
  bool motion_distortion = true;     // false: the whole scan from the pose at scan start
};

struct SimulatedScan {
  LidarScan raw;    // sensor units (mm, timestamps), packet-encodable; staggered
  RangeImage image; // the same in metres (NaN = no return)
  std::vector<Eigen::Isometry3d> column_poses;  // T_world_lidar at each column's time
  double start_time_s = 0.0;                    // time of column 0
  // Ground truth per pixel (row-major H x W): the exact range to the first
  // surface along the beam's centre ray, before noise, dropout, min range,
  // divergence and millimetre quantisation; NaN where the ray reaches no
  // surface or the column is outside the column window.
  std::vector<float> true_range;
  // Ground truth per pixel (row-major H x W), for the same centre ray: 0 where
  // it met the static scene or nothing, k + 1 where its first surface is moving
  // actor k (LidarSimulator::setActors). All 0 without actors.
  std::vector<uint16_t> true_actor;
};

// What the scan holds (raw is single-return with signal, the fields of LEGACY
// and RNG19_RFL8_SIG16_NIR16), per pixel and column:
//  - column u fires at start + u / (W * frequency); timestamp_ns is that time
//    in nanoseconds of the trajectory's clock (so t = 0 gives timestamp 0),
//    measurement_id = u, status 1 (valid) inside the column window and 0
//    outside (no pixels there), encoder_count = u * 90112 / W (LEGACY ticks);
//  - the beam of pixel (u, v) starts at o + n d (Pi^-1's offset o and
//    direction d, n = |beam origin|), so that unprojecting the reported range
//    r = n + distance lands on the hit surface;
//  - range in whole millimetres as the sensor reports (0 = no return), image
//    in metres from it (toRangeImage); rays reach max_range_m plus six noise
//    sigmas, so noise can carry a surface just beyond max range inside;
//  - reflectivity from a grey Lambertian world (albedo 50 %): 50 * |cos| of
//    the incidence angle; signal falls with the square of the range
//    (reflectivity * 100 / r^2 photons, at least 1 for a return); near_ir 0.
// Noise and dropout come from a stream per (seed, frame_id, column): the scan
// is the same whatever the number of threads.
class LidarSimulator {
 public:
  // Millimetre quantisation as the sensor reports (RangeImage derived from raw).
  // The caster must outlive the simulator. Throws std::invalid_argument for a
  // missing model, bad effects or a frequency that is not positive.
  LidarSimulator(LidarModelConstPtr model, const RayCaster& caster, SensorEffects effects,
                 uint32_t seed, double frequency_hz = 10.0);
  // Moving actors, cast together with the scene: each column sees them posed
  // at its own time (the scan start without motion distortion), and the
  // nearer of scene and actor wins. nullptr or an empty list: none, and the
  // scans are exactly those of a simulator without actors. The list must
  // outlive the simulator; at most 65534 actors.
  void setActors(const std::vector<MovingActor>* actors);

  // The revolution whose column 0 fires at start_time_s; frame_id is stored in raw.
  // Parallel over columns (TBB). Throws std::out_of_range when the trajectory
  // does not cover the revolution's time span, std::invalid_argument for a
  // negative start time.
  SimulatedScan simulate(const Trajectory& trajectory, double start_time_s, uint32_t frame_id) const;
  // The same into an existing scan, whose buffers are reused.
  void simulate(const Trajectory& trajectory, double start_time_s, uint32_t frame_id,
                SimulatedScan& scan) const;

  double columnTime(double start_time_s, int column) const {
    return start_time_s + column / (columns_ * frequency_hz_);
  }
  const LidarModelConstPtr& model() const { return model_; }
  const SensorEffects& effects() const { return effects_; }
  double frequencyHz() const { return frequency_hz_; }

 private:
  struct ColumnBuffers;
  void simulateColumn(int column, const Eigen::Isometry3d& pose, uint32_t frame_id,
                      SimulatedScan& scan, ColumnBuffers& buffers) const;
  void castActors(double time_s, float reach_m, ColumnBuffers& buffers) const;

  LidarModelConstPtr model_;
  const RayCaster& caster_;
  const std::vector<MovingActor>* actors_ = nullptr;
  SensorEffects effects_;
  uint32_t seed_;
  double frequency_hz_;
  int rows_ = 0, columns_ = 0;
  float beam_origin_norm_ = 0.0f;  // n
  // Sub-ray directions in a frame whose z axis is the beam: the centre ray
  // first, then a ring at half the divergence when it is > 0.
  std::vector<Eigen::Vector3d> footprint_;
};

}  // namespace range_image_mapping::simulation
