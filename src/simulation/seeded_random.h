// Reproducible random numbers for the simulator: the same seed gives the same
// numbers on every platform and standard library (std distributions do not
// promise that), and independent streams are cheap to derive from a key such
// as (seed, frame, column), so results never depend on thread scheduling.
#pragma once

#include <cmath>
#include <cstdint>
#include <initializer_list>

namespace range_image_mapping::simulation {

// splitmix64 (Steele, Lea, Flood 2014): a Weyl sequence through a strong
// 64-bit finaliser.
constexpr uint64_t kGoldenGamma = 0x9E3779B97F4A7C15ull;
inline uint64_t mixBits(uint64_t value) {
  value = (value ^ (value >> 30)) * 0xBF58476D1CE4E5B9ull;
  value = (value ^ (value >> 27)) * 0x94D049BB133111EBull;
  return value ^ (value >> 31);
}

class SeededRandom {
 public:
  // One stream per key, e.g. {seed, frame, column}.
  SeededRandom(std::initializer_list<uint64_t> key) {
    for (uint64_t part : key) state_ = mixBits(state_ ^ part) + kGoldenGamma;
  }

  uint64_t next() { return mixBits(state_ += kGoldenGamma); }
  // Uniform in [0, 1), 53 random bits.
  double uniform() { return (next() >> 11) * 0x1.0p-53; }
  double uniform(double low, double high) { return low + (high - low) * uniform(); }
  // Standard normal by Marsaglia's polar method, which makes two at a time
  // (the second is kept for the next call) with no trigonometry.
  double gaussian() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double x, y, radius_squared;
    do {
      x = 2.0 * uniform() - 1.0;
      y = 2.0 * uniform() - 1.0;
      radius_squared = x * x + y * y;
    } while (radius_squared >= 1.0 || radius_squared == 0.0);
    const double scale = std::sqrt(-2.0 * std::log(radius_squared) / radius_squared);
    spare_ = y * scale;
    has_spare_ = true;
    return x * scale;
  }

 private:
  uint64_t state_ = 0x243F6A8885A308D3ull;  // any fixed start
  double spare_ = 0.0;
  bool has_spare_ = false;
};

}  // namespace range_image_mapping::simulation
