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

#endif
