//
// # Yocto/Math: vectors, frames and rays on GLM
//
// GLM supplies the vector and matrix types; this header names them as Yocto/GL
// does (`vec3f`, `mat4f`) and adds the few things GLM lacks: affine frames
// (`frame3f` with axes `x, y, z` and origin `o`), rays, bounding boxes and the
// guarded scalar helpers (`safe_sqrt`, `safe_asin`) that numerical code needs.
//

#ifndef YOCTO_MATH_H_
#define YOCTO_MATH_H_

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <glm/glm.hpp>
#include <limits>

// -----------------------------------------------------------------------------
// TYPES AND CONSTANTS
// -----------------------------------------------------------------------------
namespace yocto {

using vec2f = glm::vec2;
using vec3f = glm::vec3;
using vec4f = glm::vec4;
using vec2i = glm::ivec2;
using vec3i = glm::ivec3;
using vec4i = glm::ivec4;
using mat3f = glm::mat3;
using mat4f = glm::mat4;
using byte  = unsigned char;

// Vector functions come from GLM (found by argument-dependent lookup too).
using glm::cross;
using glm::distance;
using glm::dot;
using glm::length;
using glm::normalize;

inline constexpr float pif     = 3.14159265358979323846f;
inline constexpr float flt_max = std::numeric_limits<float>::max();
inline constexpr float flt_min = std::numeric_limits<float>::lowest();
inline constexpr float flt_eps = std::numeric_limits<float>::epsilon();

}  // namespace yocto

// -----------------------------------------------------------------------------
// SCALAR AND VECTOR HELPERS
// -----------------------------------------------------------------------------
namespace yocto {

inline float sqr(float a) { return a * a; }
// x^n for a constant n by repeated squaring: log2(n) squarings and a multiply
// per set bit (x^20 = ((x^4 x)^2)^2, five multiplies).
template <int n>
inline float pow_int(float x) {
  static_assert(n >= 0);
  if constexpr (n == 0) return 1;
  else if constexpr (n % 2 == 0) return sqr(pow_int<n / 2>(x));
  else return x * pow_int<n - 1>(x);
}
inline float radians(float degrees) { return degrees * pif / 180; }
inline float degrees(float radians) { return radians * 180 / pif; }
// Square root and arc sine clamped to their domain: round-off can push the
// argument slightly outside it.
inline float safe_sqrt(float a) { return std::sqrt(std::max(a, 0.0f)); }
inline float safe_asin(float a) { return std::asin(std::clamp(a, -1.0f, 1.0f)); }
inline float safe_acos(float a) { return std::acos(std::clamp(a, -1.0f, 1.0f)); }

inline float max_component(const vec3f& a) { return std::max({a.x, a.y, a.z}); }
inline float min_component(const vec3f& a) { return std::min({a.x, a.y, a.z}); }
inline float mean(const vec3f& a) { return (a.x + a.y + a.z) / 3; }
inline float luminance(const vec3f& a) {
  return 0.2126f * a.x + 0.7152f * a.y + 0.0722f * a.z;
}
inline bool isfinite(const vec3f& a) {
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
}
// Normalizes, returning zero instead of NaN for a zero vector.
inline vec3f safe_normalize(const vec3f& a) {
  auto l = length(a);
  return l > 0 ? a / l : vec3f{0, 0, 0};
}
// Reflects w about the normal n; both point away from the surface.
inline vec3f reflect(const vec3f& w, const vec3f& n) {
  return -w + 2 * dot(n, w) * n;
}
// Orthonormal basis around z (Duff et al., Building an Orthonormal Basis,
// Revisited, JCGT 2017).
inline mat3f basis_fromz(const vec3f& v) {
  auto z    = normalize(v);
  auto sign = std::copysign(1.0f, z.z);
  auto a    = -1.0f / (sign + z.z);
  auto b    = z.x * z.y * a;
  auto x    = vec3f{1 + sign * z.x * z.x * a, sign * b, -sign * z.x};
  auto y    = vec3f{b, sign + z.y * z.y * a, -z.y};
  return {x, y, z};
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// FRAMES
// -----------------------------------------------------------------------------
namespace yocto {

// Affine frame: axes x, y, z (not necessarily orthonormal) and origin o.
struct frame3f {
  vec3f x = {1, 0, 0};
  vec3f y = {0, 1, 0};
  vec3f z = {0, 0, 1};
  vec3f o = {0, 0, 0};
};

inline const frame3f identity3x4f = {};

inline bool operator==(const frame3f& a, const frame3f& b) {
  return a.x == b.x && a.y == b.y && a.z == b.z && a.o == b.o;
}
inline bool operator!=(const frame3f& a, const frame3f& b) { return !(a == b); }

inline mat3f frame_rotation(const frame3f& a) { return {a.x, a.y, a.z}; }
inline frame3f make_frame(const mat3f& m, const vec3f& o) {
  return {m[0], m[1], m[2], o};
}
inline mat4f frame_to_mat(const frame3f& a) {
  return {vec4f{a.x, 0}, vec4f{a.y, 0}, vec4f{a.z, 0}, vec4f{a.o, 1}};
}
inline frame3f mat_to_frame(const mat4f& m) {
  return {vec3f{m[0]}, vec3f{m[1]}, vec3f{m[2]}, vec3f{m[3]}};
}

// Composition: (a * b) applied to p is a applied to (b applied to p).
inline frame3f operator*(const frame3f& a, const frame3f& b) {
  auto ra = frame_rotation(a);
  return make_frame(ra * frame_rotation(b), ra * b.o + a.o);
}
// Inverse; the transpose suffices for rigid frames.
inline frame3f inverse(const frame3f& a, bool non_rigid = true) {
  auto rinv = non_rigid ? glm::inverse(frame_rotation(a))
                        : glm::transpose(frame_rotation(a));
  return make_frame(rinv, -(rinv * a.o));
}

inline vec3f transform_point(const frame3f& a, const vec3f& p) {
  return a.x * p.x + a.y * p.y + a.z * p.z + a.o;
}
inline vec3f transform_vector(const frame3f& a, const vec3f& v) {
  return a.x * v.x + a.y * v.y + a.z * v.z;
}
inline vec3f transform_direction(const frame3f& a, const vec3f& v) {
  return normalize(transform_vector(a, v));
}
// Normals transform by the inverse transpose when the frame is not rigid.
inline vec3f transform_normal(const frame3f& a, const vec3f& n) {
  auto m = glm::transpose(glm::inverse(frame_rotation(a)));
  return normalize(m * n);
}
// Scale factor that a frame applies to lengths (exact for uniform scaling).
inline float frame_scale(const frame3f& a) {
  return std::cbrt(std::abs(glm::determinant(frame_rotation(a))));
}

// Frame at o with z along the given direction.
inline frame3f frame_fromz(const vec3f& o, const vec3f& z) {
  return make_frame(basis_fromz(z), o);
}
// Camera-style frame at eye looking at center: -z points to center.
inline frame3f lookat_frame(
    const vec3f& eye, const vec3f& center, const vec3f& up) {
  auto w = normalize(eye - center);
  auto u = normalize(cross(up, w));
  auto v = normalize(cross(w, u));
  return {u, v, w, eye};
}
inline frame3f translation_frame(const vec3f& t) {
  return {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, t};
}
inline frame3f scaling_frame(const vec3f& s) {
  return {{s.x, 0, 0}, {0, s.y, 0}, {0, 0, s.z}, {0, 0, 0}};
}
// Rotation about an axis by an angle in radians.
inline frame3f rotation_frame(const vec3f& axis, float angle) {
  auto a = normalize(axis);
  auto s = std::sin(angle), c = std::cos(angle);
  auto r = mat3f{
      vec3f{c + (1 - c) * a.x * a.x, (1 - c) * a.x * a.y + s * a.z,
          (1 - c) * a.x * a.z - s * a.y},
      vec3f{(1 - c) * a.x * a.y - s * a.z, c + (1 - c) * a.y * a.y,
          (1 - c) * a.y * a.z + s * a.x},
      vec3f{(1 - c) * a.x * a.z + s * a.y, (1 - c) * a.y * a.z - s * a.x,
          c + (1 - c) * a.z * a.z}};
  return make_frame(r, {0, 0, 0});
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// RAYS AND BOUNDS
// -----------------------------------------------------------------------------
namespace yocto {

inline constexpr float ray_eps = 1e-4f;

struct ray3f {
  vec3f o    = {0, 0, 0};
  vec3f d    = {0, 0, 1};
  float tmin = ray_eps;
  float tmax = flt_max;
};

struct bbox3f {
  vec3f min = {flt_max, flt_max, flt_max};
  vec3f max = {flt_min, flt_min, flt_min};
};

inline bbox3f merge(const bbox3f& a, const vec3f& p) {
  return {glm::min(a.min, p), glm::max(a.max, p)};
}
inline bbox3f merge(const bbox3f& a, const bbox3f& b) {
  return {glm::min(a.min, b.min), glm::max(a.max, b.max)};
}
inline bool empty(const bbox3f& a) { return a.min.x > a.max.x; }
inline vec3f center(const bbox3f& a) { return (a.min + a.max) / 2.0f; }
inline vec3f size(const bbox3f& a) { return a.max - a.min; }

}  // namespace yocto

// -----------------------------------------------------------------------------
// HASHING
// -----------------------------------------------------------------------------
namespace yocto {

// A 64-bit hash of bytes fed in pieces, for fingerprints and checksums (not
// for security): eight bytes at a time, each mixed in with the block steps
// of MurmurHash3 x64 (Appleby, 2011), then the count of bytes, so that
// arrays of different lengths differ.
struct hash_stream {
  uint64_t hash = 0x9e3779b97f4a7c15ull;
};
inline void hash_word(hash_stream& stream, uint64_t word) {
  word *= 0x87c37b91114253d5ull;
  word = (word << 31) | (word >> 33);
  word *= 0x4cf5ad432745937full;
  stream.hash ^= word;
  stream.hash = ((stream.hash << 27) | (stream.hash >> 37)) * 5 + 0x52dce729;
}
// The bytes as 8-byte words (the last zero-padded), without their count:
// blocks of whole words hash as the array they make up.
inline void hash_words(hash_stream& stream, const void* data, size_t size) {
  auto bytes = (const unsigned char*)data;
  for (size_t i = 0; i < size; i += 8) {
    auto word = (uint64_t)0;
    std::memcpy(&word, bytes + i, std::min(size - i, (size_t)8));
    hash_word(stream, word);
  }
}
inline void hash_bytes(hash_stream& stream, const void* data, size_t size) {
  hash_words(stream, data, size);
  hash_word(stream, size);
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// EXACT SUMS
// -----------------------------------------------------------------------------
namespace yocto {

// A sum of RGB samples that does not depend on the order or the grouping of
// its terms, so that a render split into sample ranges and merged gives the
// same bits as one render. Each channel is a 192-bit two's-complement
// integer counting units of 2^-64 (three words, least significant first):
// integer additions are associative and commutative, even when they wrap.
// A sample component x is added as x * 2^64 rounded toward zero, which is
// exact for |x| >= 2^-41 (a float's 24 bits then all lie above 2^-64);
// smaller components lose at most 2^-64 each. Components must be finite and
// below fixed_sum_max_sample in magnitude: with fewer than 2^31 samples the
// sum then stays below 2^127, within the 191 bits of magnitude.
struct fixed_sum3 {
  uint64_t words[9] = {};  // channel c in words[3c ... 3c + 2]
};
inline constexpr float fixed_sum_max_sample = 0x1p96f;

inline bool operator==(const fixed_sum3& a, const fixed_sum3& b) {
  return std::memcmp(a.words, b.words, sizeof(a.words)) == 0;
}

// Adds the 192-bit integer b to a, modulo 2^192.
inline void add_fixed_words(uint64_t* a, const uint64_t* b) {
  auto carry = (uint64_t)0;
  for (auto i = 0; i < 3; i++) {
    auto sum = (unsigned __int128)a[i] + b[i] + carry;
    a[i]     = (uint64_t)sum;
    carry    = (uint64_t)(sum >> 64);
  }
}

// Two's complement negation, modulo 2^192.
inline void negate_fixed_words(uint64_t* words) {
  const uint64_t one[3] = {1, 0, 0};
  for (auto i = 0; i < 3; i++) words[i] = ~words[i];
  add_fixed_words(words, one);
}

// The 192-bit value of x * 2^64 rounded toward zero (|x| below
// fixed_sum_max_sample, finite).
inline void float_to_fixed_words(float x, uint64_t* words) {
  words[0] = words[1] = words[2] = 0;
  auto bits = (uint32_t)0;
  std::memcpy(&bits, &x, sizeof(bits));
  auto exponent = (int)((bits >> 23) & 0xff);
  if (exponent == 0) return;  // zero or subnormal: below 2^-126, so 0 units
  // x = mantissa * 2^(exponent - 150) = mantissa * 2^(exponent - 86) units.
  auto mantissa = (uint64_t)((bits & 0x7fffff) | 0x800000);
  auto shift    = exponent - 86;
  if (shift <= -24) return;
  if (shift < 0) {
    words[0] = mantissa >> -shift;
  } else {
    auto word = shift / 64, bit = shift % 64;
    words[word] = mantissa << bit;
    if (bit > 40 && word < 2) words[word + 1] = mantissa >> (64 - bit);
  }
  if (bits >> 31) negate_fixed_words(words);
}

// Adds x * 2^64 rounded toward zero to the 192-bit integer at words. Values
// below 2^63 (all but absurd samples) take 128-bit arithmetic with a carry
// or borrow into the top word: ten times faster than the general path.
inline void add_fixed_float(uint64_t* words, float x) {
  auto bits = (uint32_t)0;
  std::memcpy(&bits, &x, sizeof(bits));
  auto exponent = (int)((bits >> 23) & 0xff);
  auto shift    = exponent - 86;  // x = mantissa * 2^shift units
  if (exponent == 0 || shift <= -24) return;
  if (shift + 24 > 127) {
    uint64_t value[3];
    float_to_fixed_words(x, value);
    add_fixed_words(words, value);
    return;
  }
  auto mantissa = (unsigned __int128)((bits & 0x7fffff) | 0x800000);
  auto value    = shift >= 0 ? mantissa << shift : mantissa >> -shift;
  auto low      = (unsigned __int128)words[1] << 64 | words[0];
  auto result   = (bits >> 31) ? low - value : low + value;
  // Carry (the sum wrapped below low) or borrow (the difference above it).
  if ((bits >> 31) ? result > low : result < low) words[2] += (bits >> 31) ? ~0ull : 1ull;
  words[0] = (uint64_t)result;
  words[1] = (uint64_t)(result >> 64);
}

inline void add_fixed(fixed_sum3& sum, const vec3f& sample) {
  for (auto c = 0; c < 3; c++) add_fixed_float(sum.words + 3 * c, sample[c]);
}
inline void add_fixed(fixed_sum3& sum, const fixed_sum3& other) {
  for (auto c = 0; c < 3; c++) add_fixed_words(sum.words + 3 * c, other.words + 3 * c);
}

// The sum as doubles (rounded; the same bits for the same sum).
inline glm::dvec3 fixed_to_double(const fixed_sum3& sum) {
  auto value = glm::dvec3{0, 0, 0};
  for (auto c = 0; c < 3; c++) {
    uint64_t words[3] = {sum.words[3 * c], sum.words[3 * c + 1], sum.words[3 * c + 2]};
    auto negative = (words[2] >> 63) != 0;
    if (negative) negate_fixed_words(words);
    // Units of 2^-64: words[0] * 2^-64 + words[1] + words[2] * 2^64.
    auto magnitude = std::ldexp((double)words[0], -64) + (double)words[1] +
                     std::ldexp((double)words[2], 64);
    value[c] = negative ? -magnitude : magnitude;
  }
  return value;
}

}  // namespace yocto

#endif
