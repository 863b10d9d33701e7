#include "range_image_mapping/simulation/speed_profile.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace range_image_mapping::simulation {

SpeedProfile::SpeedProfile(double start_time_s, double start_distance_m, double start_speed_mps)
    : start_time_s_(start_time_s), start_distance_m_(start_distance_m), start_speed_mps_(start_speed_mps) {
  if (!(std::isfinite(start_time_s) && std::isfinite(start_distance_m) && std::isfinite(start_speed_mps)))
    throw std::invalid_argument("SpeedProfile: start values must be finite");
}

SpeedProfile& SpeedProfile::changeSpeed(double duration_s, double target_mps) {
  if (!(std::isfinite(duration_s) && duration_s > 0.0 && std::isfinite(target_mps)))
    throw std::invalid_argument("SpeedProfile: a phase needs a positive duration and a finite speed, got " +
                                std::to_string(duration_s) + " s, " + std::to_string(target_mps) + " m/s");
  Phase phase;
  phase.start_time_s = endTime();
  phase.duration_s = duration_s;
  phase.start_distance_m = distance(phase.start_time_s);
  phase.start_speed_mps = endSpeed();
  phase.end_speed_mps = target_mps;
  phases_.push_back(phase);
  return *this;
}

double SpeedProfile::endTime() const {
  return phases_.empty() ? start_time_s_ : phases_.back().start_time_s + phases_.back().duration_s;
}

double SpeedProfile::endSpeed() const {
  return phases_.empty() ? start_speed_mps_ : phases_.back().end_speed_mps;
}

const SpeedProfile::Phase* SpeedProfile::phaseAt(double time_s) const {
  if (phases_.empty() || time_s < start_time_s_) return nullptr;
  // The last phase starting at or before time_s (after the end: the last one).
  const auto after = std::upper_bound(phases_.begin(), phases_.end(), time_s,
                                      [](double time, const Phase& phase) { return time < phase.start_time_s; });
  return &*(after - 1);
}

// Within a phase, x = (t - t0) / T in [0, 1]:
//   v = v0 + dv (3x^2 - 2x^3),  s = s0 + T (v0 x + dv (x^3 - x^4 / 2)),  a = dv 6x (1 - x) / T.
double SpeedProfile::distance(double time_s) const {
  const Phase* phase = phaseAt(time_s);
  if (!phase) return start_distance_m_ + start_speed_mps_ * (time_s - start_time_s_);
  const double elapsed = time_s - phase->start_time_s;
  const double change = phase->end_speed_mps - phase->start_speed_mps;
  if (elapsed >= phase->duration_s)  // past the last phase
    return phase->start_distance_m +
           phase->duration_s * (phase->start_speed_mps + 0.5 * change) +
           phase->end_speed_mps * (elapsed - phase->duration_s);
  const double x = elapsed / phase->duration_s;
  return phase->start_distance_m +
         phase->duration_s * (phase->start_speed_mps * x + change * (x * x * x - 0.5 * x * x * x * x));
}

double SpeedProfile::speed(double time_s) const {
  const Phase* phase = phaseAt(time_s);
  if (!phase) return start_speed_mps_;
  const double x = std::min((time_s - phase->start_time_s) / phase->duration_s, 1.0);
  return phase->start_speed_mps + (phase->end_speed_mps - phase->start_speed_mps) * x * x * (3.0 - 2.0 * x);
}

double SpeedProfile::acceleration(double time_s) const {
  const Phase* phase = phaseAt(time_s);
  if (!phase) return 0.0;
  const double x = (time_s - phase->start_time_s) / phase->duration_s;
  if (x >= 1.0) return 0.0;
  return (phase->end_speed_mps - phase->start_speed_mps) * 6.0 * x * (1.0 - x) / phase->duration_s;
}

}  // namespace range_image_mapping::simulation
