//
// # Yocto/Sampling: random numbers and warps
//
// A PCG32 generator (O'Neill, PCG: A Family of Simple Fast Space-Efficient
// Statistically Good Algorithms for Random Number Generation, 2014) and the
// warps from uniform numbers to directions and points that a path tracer uses,
// each with its pdf; and the sample sequences of a pixel: Owen-scrambled
// Sobol points (Burley, Practical Hash-based Owen Scrambling, JCGT 2020) or
// independent PCG numbers, both pure functions of (seed, pixel, sample index).
//

#ifndef YOCTO_SAMPLING_H_
#define YOCTO_SAMPLING_H_

#include <array>
#include <string>
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
// SCRAMBLED SOBOL POINTS
// -----------------------------------------------------------------------------
namespace yocto {

inline constexpr uint32_t reverse_bits(uint32_t x) {
  x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
  x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
  x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
  x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);
  return (x >> 16) | (x << 16);
}

// The first two dimensions of the Sobol sequence as 0.32 fixed point: the
// van der Corput radical inverse, and the dimension whose generator matrix
// is Pascal's triangle mod 2 (each direction number is the previous one xor
// itself shifted right). Together a (0,2)-sequence in base 2.
// Dimension 1 is generated bit-reversed, as the scrambles below use it.
inline uint32_t sobol_dimension0(uint32_t index) { return reverse_bits(index); }
// Sobol dimensions 1, 2 and 3 by their direction numbers v_k = m_k 2^(32 - k):
// primitive polynomials x + 1, x^2 + x + 1 and x^3 + x + 1 with the initial
// m of Joe and Kuo (Constructing Sobol Sequences with Better Two-Dimensional
// Projections, 2008: 1; 1 3; 1 3 1), the others by the recurrence of Bratley
// and Fox (1988); for x + 1 it gives Pascal's triangle. Kept bit-reversed,
// as the xor of the directions of each byte of the index, one table per byte
// position (4 KB), so that a point costs four lookups instead of a loop over
// the index's 32 bits.
// A dimension's primitive polynomial (its degree and inner coefficients, as
// Joe and Kuo write them) and initial m.
struct sobol_polynomial {
  int                     degree       = 0;
  uint32_t                coefficients = 0;
  std::array<uint32_t, 8> initial      = {};
};
// The direction numbers v_1 ... v_32 of a dimension, each bit-reversed (the
// xor of those of an index's bits is the point, bit-reversed).
inline constexpr std::array<uint32_t, 32> make_sobol_directions(
    const sobol_polynomial& polynomial) {
  auto [degree, coefficients, initial] = polynomial;
  auto m = std::array<uint32_t, 33>{};
  for (auto k = 1; k <= 32; k++) {
    if (k <= degree) {
      m[k] = initial[k - 1];
      continue;
    }
    m[k] = m[k - degree] ^ (m[k - degree] << degree);
    for (auto j = 1; j < degree; j++) {
      if (coefficients >> (degree - 1 - j) & 1) m[k] ^= m[k - j] << j;
    }
  }
  auto directions = std::array<uint32_t, 32>{};
  for (auto k = 1; k <= 32; k++) directions[k - 1] = reverse_bits(m[k] << (32 - k));
  return directions;
}
inline constexpr std::array<std::array<uint32_t, 256>, 4> make_sobol_tables(
    const sobol_polynomial& polynomial) {
  auto directions = make_sobol_directions(polynomial);
  auto tables     = std::array<std::array<uint32_t, 256>, 4>{};
  for (auto byte = 0; byte < 4; byte++) {
    for (auto value = 0; value < 256; value++) {
      auto result = 0u;
      for (auto bit = 0; bit < 8; bit++) {
        if (value >> bit & 1) result ^= directions[byte * 8 + bit];
      }
      tables[byte][value] = result;
    }
  }
  return tables;
}
inline constexpr auto sobol_dimension1_tables = make_sobol_tables({1, 0, {1}});
inline constexpr auto sobol_dimension2_tables = make_sobol_tables({2, 1, {1, 3}});
inline constexpr auto sobol_dimension3_tables = make_sobol_tables({3, 1, {1, 3, 1}});
// Point `index` of a dimension, bit-reversed.
inline uint32_t sobol_reversed(
    const std::array<std::array<uint32_t, 256>, 4>& tables, uint32_t index) {
  return tables[0][index & 0xff] ^ tables[1][index >> 8 & 0xff] ^
         tables[2][index >> 16 & 0xff] ^ tables[3][index >> 24];
}
inline uint32_t sobol_dimension1(uint32_t index) {
  return reverse_bits(sobol_reversed(sobol_dimension1_tables, index));
}

// A hash in which every bit is changed only as a function of the bits below
// it (additions and products carry upwards only), so that on bit-reversed
// numbers it is an Owen scramble (Laine and Karras, Stratified Sampling for
// Stochastic Transparency, 2011). The constants are Vegdahl's (Building a
// Better LK Hash, 2021): Burley's listing 2 lets the seed in by one addition
// only, so the top d digits take 2^d forms over all seeds instead of
// 2^(2^d - 1), and sub-strata of a pixel stay correlated (test_sampling).
inline uint32_t laine_karras_permutation(uint32_t x, uint32_t seed) {
  x ^= x * 0x3d20adeau;
  x += seed;
  x *= (seed >> 16) | 1u;
  x ^= x * 0x05526c56u;
  x ^= x * 0x53a22864u;
  return x;
}

// Owen scrambling of a 0.32 fixed-point number: each digit flipped by a
// random function of the digits above it. Applied to a sample index, it is
// a shuffle that maps every aligned block of 2^k indices to another one.
inline uint32_t nested_uniform_scramble(uint32_t x, uint32_t seed) {
  return reverse_bits(laine_karras_permutation(reverse_bits(x), seed));
}

// A 0.32 fixed-point number to a float in [0, 1) (its top 24 bits).
inline float fixed_to_float(uint32_t x) { return (x >> 8) * (1.0f / 16777216.0f); }

// The shuffled index and the two hashes whose halves seed the scrambles of
// point `index` of sequence `seed` (sample_sobol2f, sample_sobol4f).
struct sobol_scrambles {
  uint32_t shuffled = 0;
  uint64_t hash     = 0;
  uint64_t more     = 0;
};
inline sobol_scrambles make_sobol_scrambles(uint32_t index, uint64_t seed) {
  auto hash = hash_uint64(seed);
  return {nested_uniform_scramble(index, (uint32_t)hash), hash, hash_uint64(hash)};
}

// Point `index` of a shuffled, Owen-scrambled 2D Sobol sequence (Burley
// 2020, section 4): the same seed gives one (0,2)-sequence, other seeds
// independent ones, so that every pair of dimensions of a path is
// stratified without a table of higher Sobol dimensions.
// The scrambles work on bit-reversed values, and dimension 0 is the reversed
// index itself: reverse_bits(laine_karras_permutation(shuffled, seed)) is
// nested_uniform_scramble(sobol_dimension0(shuffled), seed) with two
// reversals less (and likewise for dimension 1).
inline vec2f sample_sobol2f(const sobol_scrambles& point) {
  auto x = reverse_bits(laine_karras_permutation(point.shuffled, (uint32_t)(point.hash >> 32)));
  auto y = reverse_bits(laine_karras_permutation(
      sobol_reversed(sobol_dimension1_tables, point.shuffled), (uint32_t)point.more));
  return {fixed_to_float(x), fixed_to_float(y)};
}
inline vec2f sample_sobol2f(uint32_t index, uint64_t seed) {
  return sample_sobol2f(make_sobol_scrambles(index, seed));
}

// Point `index` of a shuffled, Owen-scrambled 4D Sobol sequence: the four
// numbers are jointly stratified (a (3,4)-sequence; dimensions 0 and 1 a
// (0,2)-sequence), where two pairs of sample_sobol2f are stratified each on
// its own.
// Dimensions 0 and 1 are sample_sobol2f's point for the same index and seed
// (the same shuffle and scrambles); 2 and 3 are scrambled by the upper half
// of `more` and by a hash of it.
inline vec4f sample_sobol4f(uint32_t index, uint64_t seed) {
  auto point = make_sobol_scrambles(index, seed);
  auto xy    = sample_sobol2f(point);
  auto z     = reverse_bits(laine_karras_permutation(
      sobol_reversed(sobol_dimension2_tables, point.shuffled), (uint32_t)(point.more >> 32)));
  auto w     = reverse_bits(laine_karras_permutation(
      sobol_reversed(sobol_dimension3_tables, point.shuffled), (uint32_t)hash_uint64(point.more)));
  return {xy.x, xy.y, fixed_to_float(z), fixed_to_float(w)};
}

// One Sobol point across many dimensions (pbrt-v4's SobolSampler, with
// Burley's hashed Owen scrambling): the polynomials and initial m of Joe and
// Kuo's new-joe-kuo-6.21201 for dimensions 1 ... 31 (Constructing Sobol
// Sequences with Better Two-Dimensional Projections, 2008), chosen so that
// the pairs of low dimensions are nets with small t.
inline constexpr auto sobol_global_dimensions = 32;
inline constexpr auto sobol_global_polynomials =
    std::array<sobol_polynomial, sobol_global_dimensions - 1>{{
        {1, 0, {1}}, {2, 1, {1, 3}}, {3, 1, {1, 3, 1}},
        {3, 2, {1, 1, 1}}, {4, 1, {1, 1, 3, 3}}, {4, 4, {1, 3, 5, 13}},
        {5, 2, {1, 1, 5, 5, 17}}, {5, 4, {1, 1, 5, 5, 5}}, {5, 7, {1, 1, 7, 11, 19}},
        {5, 11, {1, 1, 5, 1, 1}}, {5, 13, {1, 1, 1, 3, 11}}, {5, 14, {1, 3, 5, 5, 31}},
        {6, 1, {1, 3, 3, 9, 7, 49}}, {6, 13, {1, 1, 1, 15, 21, 21}},
        {6, 16, {1, 3, 1, 13, 27, 49}}, {6, 19, {1, 1, 1, 15, 7, 5}},
        {6, 22, {1, 3, 1, 15, 13, 25}}, {6, 25, {1, 1, 5, 5, 19, 61}},
        {7, 1, {1, 3, 7, 11, 23, 15, 103}}, {7, 4, {1, 3, 7, 13, 13, 15, 69}},
        {7, 7, {1, 1, 3, 13, 7, 35, 63}}, {7, 8, {1, 3, 5, 9, 1, 25, 53}},
        {7, 14, {1, 3, 1, 13, 9, 35, 107}}, {7, 19, {1, 3, 1, 5, 27, 61, 31}},
        {7, 21, {1, 1, 5, 11, 19, 41, 61}}, {7, 28, {1, 3, 5, 3, 3, 13, 69}},
        {7, 31, {1, 1, 7, 13, 1, 19, 1}}, {7, 32, {1, 3, 7, 5, 13, 19, 59}},
        {7, 37, {1, 1, 3, 9, 25, 29, 41}}, {7, 41, {1, 3, 5, 13, 23, 1, 55}},
        {7, 42, {1, 3, 7, 3, 13, 59, 17}},
    }};
inline constexpr auto make_sobol_global_directions() {
  auto directions = std::array<std::array<uint32_t, 32>, sobol_global_dimensions>{};
  for (auto k = 0; k < 32; k++) directions[0][k] = 1u << k;  // van der Corput
  for (auto d = 1; d < sobol_global_dimensions; d++)
    directions[d] = make_sobol_directions(sobol_global_polynomials[d - 1]);
  return directions;
}
inline constexpr auto sobol_global_directions = make_sobol_global_directions();

// Dimension `dimension` of point `index`, bit-reversed: the xor of the
// directions of the index's set bits (a pixel's few samples have few).
inline uint32_t sobol_global_reversed(int dimension, uint32_t index) {
  auto& directions = sobol_global_directions[dimension];
  auto  result     = 0u;
  for (; index != 0; index &= index - 1) result ^= directions[__builtin_ctz(index)];
  return result;
}

// Dimensions 2 slot and 2 slot + 1 of point `index` of the Sobol sequence
// scrambled by `key`: every dimension has its own Owen scramble, and the
// points of all slots are one point (not shuffled), so that the projections
// of the sequence onto pairs of dimensions across slots are nets as well.
inline vec2f sample_sobol_global2f(uint32_t index, uint64_t key, int slot) {
  auto hash = hash_uint64(key ^ (0x676c6f62616cULL + (uint64_t)slot));  // "global"
  auto x    = reverse_bits(laine_karras_permutation(
      sobol_global_reversed(2 * slot, index), (uint32_t)hash));
  auto y    = reverse_bits(laine_karras_permutation(
      sobol_global_reversed(2 * slot + 1, index), (uint32_t)(hash >> 32)));
  return {fixed_to_float(x), fixed_to_float(y)};
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// SAMPLE SEQUENCES OF A PIXEL
// -----------------------------------------------------------------------------
namespace yocto {

// Scrambled Sobol pairs (padded: each pair its own shuffled sequence), one
// scrambled Sobol point across the pairs of `global_slots` (the others
// padded), or independent numbers.
enum struct sequence_type { sobol, independent, global_sobol };
inline const auto sequence_names = std::array<std::string, 3>{
    "sobol", "independent", "global-sobol"};

// The numbers of one pixel sample. They are drawn as pairs of dimensions at
// fixed positions (a path's bounce k uses the same pairs in every sample);
// Sobol pairs below `sobol_pairs`, a hashed PCG stream past them. With
// global_sobol, pair p below both `sobol_pairs` and `global_pairs` takes the
// dimensions of slot global_slots[p] of the global point, if not negative.
struct sequence_state {
  sequence_type type        = sequence_type::sobol;
  uint64_t      key         = 0;  // hash of seed and pixel
  uint32_t      index       = 0;  // sample index
  int           sobol_pairs = 0;
  const int8_t* global_slots = nullptr;
  int           global_pairs = 0;  // entries of global_slots
  rng_state     rng         = {};
};

// The sequence of sample `sample` of pixel `pixel`: a pure function of its
// arguments, so that any range of samples renders alone.
inline sequence_state make_sequence(sequence_type type, uint64_t seed, int64_t pixel,
    uint32_t sample, int sobol_pairs, const int8_t* global_slots = nullptr,
    int global_pairs = 0) {
  auto seed_hash    = hash_uint64(seed);
  auto state        = sequence_state{};
  state.type        = type;
  state.key         = hash_uint64(seed_hash ^ (uint64_t)pixel);
  state.index       = sample;
  state.sobol_pairs = type != sequence_type::independent ? sobol_pairs : 0;
  if (type == sequence_type::global_sobol && global_slots) {
    state.global_slots = global_slots;
    state.global_pairs = global_pairs;
  }
  auto key   = seed_hash ^ hash_uint64(((uint64_t)pixel << 24) ^ (uint64_t)sample);
  state.rng  = make_rng(hash_uint64(key), (uint64_t)pixel);
  return state;
}

// The pair of dimensions `pair` of the sample.
inline vec2f sample_sequence2f(sequence_state& state, int pair) {
  if (pair < state.sobol_pairs) {
    if (pair < state.global_pairs && state.global_slots[pair] >= 0)
      return sample_sobol_global2f(state.index, state.key, state.global_slots[pair]);
    return sample_sobol2f(state.index, state.key ^ ((uint64_t)pair << 40));
  }
  return rand2f(state.rng);
}

// Pairs `pair` and `pair + 1` of the sample as four jointly stratified
// numbers (one 4D Sobol point) where both are Sobol pairs.
inline vec4f sample_sequence4f(sequence_state& state, int pair) {
  if (pair + 1 < state.sobol_pairs && !state.global_slots) {
    return sample_sobol4f(state.index, state.key ^ ((uint64_t)pair << 40));
  }
  auto a = sample_sequence2f(state, pair), b = sample_sequence2f(state, pair + 1);
  return {a.x, a.y, b.x, b.y};
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
