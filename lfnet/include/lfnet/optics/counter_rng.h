// Counter-based random numbers: every value is a pure function of (seed, stream, index), so
// codes and noise are reproducible bit for bit whatever the thread count or evaluation order,
// and independent of LibTorch's generators (which may change between versions).
#pragma once

#include <cmath>
#include <cstdint>

namespace lfnet::optics {

// SplitMix64's output function (Steele, Lea & Flood 2014): a bijective 64-bit mixer.
inline uint64_t mix64(uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

// The random numbers of one (seed, stream) pair, addressed by a 64-bit index. Streams separate
// uses of one seed (e.g. mask codes and shot noise), so they never share values.
class CounterRng {
 public:
  static constexpr uint64_t kGolden = 0x9e3779b97f4a7c15ULL;

  CounterRng(uint64_t seed, uint64_t stream)
      : key_(mix64(mix64(seed + kGolden) ^ (stream * 0xd1b54a32d192ed03ULL + 1))) {}

  // 64 random bits: value `index` of the SplitMix64 sequence started at this stream's key.
  uint64_t bits(uint64_t index) const { return mix64(key_ + (index + 1) * kGolden); }

  // Uniform in the open interval (0, 1), 53 bits.
  double uniform(uint64_t index) const {
    return (static_cast<double>(bits(index) >> 11) + 0.5) * 0x1.0p-53;
  }

  // Standard normal from the uniforms 2 index and 2 index + 1 (Box-Muller).
  double normal(uint64_t index) const {
    const double r = std::sqrt(-2.0 * std::log(uniform(2 * index)));
    return r * std::cos(6.283185307179586 * uniform(2 * index + 1));
  }

  // A sub-stream for one element that needs a variable number of draws (rejection sampling).
  CounterRng sub(uint64_t index) const { return CounterRng(key_, index, 0); }

 private:
  CounterRng(uint64_t key, uint64_t index, int) : key_(mix64(key ^ mix64(index + kGolden))) {}
  uint64_t key_;
};

// Named streams of lfnet's random numbers, fixed so that results never change silently.
namespace stream {
constexpr uint64_t kMaskCode = 1;
constexpr uint64_t kApertureCode = 2;
constexpr uint64_t kRandomMatrix = 3;
constexpr uint64_t kExposureCode = 4;
constexpr uint64_t kTimeApertureCode = 5;
constexpr uint64_t kGaussianNoise = 11;
constexpr uint64_t kShotNoise = 12;
constexpr uint64_t kReadNoise = 13;
constexpr uint64_t kGainPattern = 14;
}  // namespace stream

}  // namespace lfnet::optics
