// Motion along a line as a function of time: the distance travelled, made of
// phases in which the speed changes smoothly from one value to another. Drives
// the stop-and-go ego car and the actors of the traffic scenario.
#pragma once

#include <vector>

namespace range_image_mapping::simulation {

class SpeedProfile {
 public:
  // At start_time_s the distance is start_distance_m and the speed start_speed_mps.
  explicit SpeedProfile(double start_time_s = 0.0, double start_distance_m = 0.0,
                        double start_speed_mps = 0.0);

  // Appends a phase of duration_s (> 0) in which the speed goes from the
  // current end speed to target_mps along a smoothstep, 3x^2 - 2x^3: the
  // acceleration is continuous, zero at both ends, its peak 1.5 times the mean.
  // Throws std::invalid_argument for a duration that is not positive or a value
  // that is not finite.
  SpeedProfile& changeSpeed(double duration_s, double target_mps);
  // Appends a phase at constant speed (a standstill when the speed is 0).
  SpeedProfile& hold(double duration_s) { return changeSpeed(duration_s, endSpeed()); }

  // Defined for every time: before the first phase and after the last the
  // speed stays the start and end speed.
  double distance(double time_s) const;
  double speed(double time_s) const;
  double acceleration(double time_s) const;

  double startTime() const { return start_time_s_; }
  double endTime() const;
  double endSpeed() const;

 private:
  struct Phase {
    double start_time_s, duration_s, start_distance_m, start_speed_mps, end_speed_mps;
  };
  // The phase holding time_s (nullptr before the first).
  const Phase* phaseAt(double time_s) const;

  double start_time_s_, start_distance_m_, start_speed_mps_;
  std::vector<Phase> phases_;
};

}  // namespace range_image_mapping::simulation
