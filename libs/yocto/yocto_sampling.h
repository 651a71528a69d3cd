//
// # Yocto/Sampling: random numbers and warps
//
// A PCG32 generator (O'Neill, PCG: A Family of Simple Fast Space-Efficient
// Statistically Good Algorithms for Random Number Generation, 2014) and the
// warps from uniform numbers to directions and points that a path tracer uses,
// each with its pdf.
//

#ifndef YOCTO_SAMPLING_H_
#define YOCTO_SAMPLING_H_

#include <vector>

#include "yocto_math.h"

// -----------------------------------------------------------------------------
// RANDOM NUMBER GENERATION
// -----------------------------------------------------------------------------
namespace yocto {

// PCG32 state: 64-bit state and odd stream increment.
struct rng_state {
  uint64_t state = 0x853c49e6748fea9bULL;
  uint64_t inc   = 0xda3e39cb94b95bdbULL;
};

inline uint32_t advance_rng(rng_state& rng) {
  auto old  = rng.state;
  rng.state = old * 6364136223846793005ULL + rng.inc;
  auto xorshifted = (uint32_t)(((old >> 18u) ^ old) >> 27u);
  auto rot        = (uint32_t)(old >> 59u);
  return (xorshifted >> rot) | (xorshifted << ((~rot + 1u) & 31));
}

// Generator for a seed and a stream (sequence) number.
inline rng_state make_rng(uint64_t seed, uint64_t seq = 1) {
  auto rng  = rng_state{0, (seq << 1u) | 1u};
  advance_rng(rng);
  rng.state += seed;
  advance_rng(rng);
  return rng;
}

// SplitMix64 finaliser: decorrelates nearby integers (pixel indices).
inline uint64_t hash_uint64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

// Uniform integer in [0, n).
inline int rand1i(rng_state& rng, int n) { return (int)(advance_rng(rng) % (uint32_t)n); }
// Uniform float in [0, 1): 24 random bits, so the result never rounds to 1.
inline float rand1f(rng_state& rng) {
  return (advance_rng(rng) >> 8) * (1.0f / 16777216.0f);
}
inline vec2f rand2f(rng_state& rng) {
  auto x = rand1f(rng);
  auto y = rand1f(rng);
  return {x, y};
}
inline vec3f rand3f(rng_state& rng) {
  auto x = rand1f(rng);
  auto y = rand1f(rng);
  auto z = rand1f(rng);
  return {x, y, z};
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// WARPS
// -----------------------------------------------------------------------------
namespace yocto {

// Uniform direction on the sphere.
inline vec3f sample_sphere(const vec2f& ruv) {
  auto z = 2 * ruv.y - 1, r = safe_sqrt(1 - z * z), phi = 2 * pif * ruv.x;
  return {r * std::cos(phi), r * std::sin(phi), z};
}
inline float sample_sphere_pdf(const vec3f&) { return 1 / (4 * pif); }

// Cosine-weighted direction on the hemisphere around a normal.
inline vec3f sample_hemisphere_cos(const vec3f& normal, const vec2f& ruv) {
  auto z = safe_sqrt(ruv.y), r = safe_sqrt(1 - z * z), phi = 2 * pif * ruv.x;
  auto local = vec3f{r * std::cos(phi), r * std::sin(phi), z};
  return normalize(basis_fromz(normal) * local);
}
inline float sample_hemisphere_cos_pdf(const vec3f& normal, const vec3f& direction) {
  auto cosw = dot(normal, direction);
  return cosw <= 0 ? 0 : cosw / pif;
}

// Uniform barycentric coordinates on a triangle.
inline vec2f sample_triangle(const vec2f& ruv) {
  auto su = std::sqrt(ruv.x);
  return {1 - su, ruv.y * su};
}

// Index from a cumulative distribution (cdf.back() is the total); binary search.
inline int sample_discrete(const std::vector<float>& cdf, float r) {
  auto target = r * cdf.back();
  auto index  = (int)(std::upper_bound(cdf.begin(), cdf.end(), target) - cdf.begin());
  return std::clamp(index, 0, (int)cdf.size() - 1);
}
inline float sample_discrete_pdf(const std::vector<float>& cdf, int index) {
  if (index < 0 || index >= (int)cdf.size()) return 0;
  auto previous = index == 0 ? 0.0f : cdf[index - 1];
  return (cdf[index] - previous) / cdf.back();
}

}  // namespace yocto

#endif
