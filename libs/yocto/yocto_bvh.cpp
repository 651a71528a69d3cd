//
// Implementation of Yocto/Bvh on Embree 3.
//

#include "yocto_bvh.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

// -----------------------------------------------------------------------------
// EMBREE DEVICE
// -----------------------------------------------------------------------------
namespace yocto {

// Embree reports errors through a callback; keep the first per build.
struct embree_errors {
  std::mutex  mutex;
  std::string message;
  bool        out_of_memory = false;  // the system refused Embree's memory
};

static void embree_error_callback(void* user, RTCError code, const char* message) {
  auto errors = (embree_errors*)user;
  auto lock   = std::lock_guard{errors->mutex};
  if (errors->message.empty()) {
    errors->message = "embree error " + std::to_string((int)code) + ": " +
                      (message ? message : "unknown");
    errors->out_of_memory = code == RTC_ERROR_OUT_OF_MEMORY;
  }
}

// What Embree holds, and the most it may (0: no limit); whether an
// allocation was refused.
struct embree_monitor {
  std::shared_ptr<std::atomic<int64_t>> memory  = nullptr;
  int64_t                               limit   = 0;
  std::atomic<bool>                     refused = false;
  std::atomic<int64_t>                  peak    = 0;  // the most held at once
};

// Tracks the bytes Embree allocates and refuses, before it is made, an
// allocation beyond the limit (Embree then fails the build with
// RTC_ERROR_OUT_OF_MEMORY instead of taking the memory).
static bool embree_memory_callback(void* user, ssize_t bytes, bool post) {
  auto monitor = (embree_monitor*)user;
  auto now     = (*monitor->memory += bytes);
  if (bytes > 0 && !post && monitor->limit > 0 && now > monitor->limit) {
    *monitor->memory -= bytes;
    monitor->refused = true;
    return false;
  }
  auto peak = monitor->peak.load();
  while (now > peak && !monitor->peak.compare_exchange_weak(peak, now)) {}
  return true;
}

// A geometry whose buffer Embree could not allocate (the memory budget
// refused it: the build then fails): released, and null to the caller.
static RTCGeometry release_unbuilt(RTCGeometry geometry) {
  if (geometry) rtcReleaseGeometry(geometry);
  return nullptr;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// SHAPES
// -----------------------------------------------------------------------------
namespace yocto {

// A segment's end (0 at u = 0, 1 at u = 1): its vertex and the outward
// direction along the fibre there (not normalized; zero when the segment has
// no length), the tangent eval_fiber_point takes, also where a Bezier's
// derivative is zero.
struct fiber_end {
  int   vertex  = 0;
  vec3f outward = {0, 0, 0};
};
static fiber_end eval_fiber_end(const shape_data& shape, int element, int end) {
  auto p = [&](int i) { return vertex_position(shape, i); };
  if (!shape.lines.empty()) {
    auto& line = shape.lines[element];
    return end ? fiber_end{line.y, p(line.y) - p(line.x)}
               : fiber_end{line.x, p(line.x) - p(line.y)};
  }
  auto  curve   = curve_vertices(shape, element);
  auto  outward = end ? p(curve.w) - p(curve.z) : p(curve.x) - p(curve.y);
  if (length(outward) == 0) outward = end ? p(curve.w) - p(curve.x) : p(curve.x) - p(curve.w);
  return {end ? curve.w : curve.x, outward};
}

// Vertices as Embree's float4 (position, radius).
static vec4f fiber_vertex(const shape_data& shape, int index) {
  if (!shape.fiber_vertices.empty()) return shape.fiber_vertices[index];
  auto r = index < (int)shape.radius.size() ? shape.radius[index] : 0.001f;
  return {shape.positions[index], r};
}

// A curve's four control points as Embree's float4 (position, radius).
static std::array<vec4f, 4> curve_control_points(const shape_data& shape, const vec4i& c) {
  return {fiber_vertex(shape, c.x), fiber_vertex(shape, c.y), fiber_vertex(shape, c.z),
      fiber_vertex(shape, c.w)};
}

// Do all of an element's vertex indices fall within the shape's vertices?
template <typename Element>
static bool element_in_range(const shape_data& shape, const Element& element) {
  for (auto k = 0; k < (int)element.length(); k++)
    if (element[k] < 0 || element[k] >= num_vertices(shape)) return false;
  return true;
}

// Packed vertices (pack_fiber_vertices) are Embree's layout: the scene's
// own memory, read in place.
static void share_packed_vertices(RTCGeometry geometry, const shape_data& shape) {
  rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4,
      shape.fiber_vertices.data(), 0, sizeof(vec4f), shape.fiber_vertices.size());
}

// Embree's curve index buffers hold the first vertex of each segment and take
// the next ones consecutively. Shapes whose elements are consecutive (strands,
// elements_are_consecutive) share their vertices; others get a vertex copy per
// element.
template <typename Element>
static RTCGeometry make_curve_geometry(
    RTCDevice device, const shape_data& shape, const std::vector<Element>& elements,
    RTCGeometryType type) {
  auto geometry  = rtcNewGeometry(device, type);
  auto degree    = (int)Element::length();
  auto shared    = elements_are_consecutive(elements);
  auto nvertices = shared ? (size_t)num_vertices(shape) : elements.size() * degree;
  // Packed vertices of a strand are Embree's layout: read in place.
  auto in_place = shared && !shape.fiber_vertices.empty();
  auto vertices = (vec4f*)nullptr;
  if (in_place) {
    share_packed_vertices(geometry, shape);
  } else {
    vertices = (vec4f*)rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0,
        RTC_FORMAT_FLOAT4, sizeof(vec4f), nvertices);
    if (!vertices) return release_unbuilt(geometry);
  }
  if (shared) {
    // The first index of each element is its index buffer: the scene's own
    // memory, read in place (13 MB not copied for 3.3M segments).
    if (!in_place)
      for (auto i = 0; i < (int)nvertices; i++) vertices[i] = fiber_vertex(shape, i);
    rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT,
        elements.data(), 0, sizeof(Element), elements.size());
  } else {
    auto indices = (uint32_t*)rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0,
        RTC_FORMAT_UINT, sizeof(uint32_t), elements.size());
    if (!indices) return release_unbuilt(geometry);
    for (auto i = 0; i < (int)elements.size(); i++) {
      for (auto k = 0; k < degree; k++)
        vertices[i * degree + k] = fiber_vertex(shape, elements[i][k]);
      indices[i] = i * degree;
    }
  }
  // Linear curves join smoothly only where told that a neighbor exists.
  if (degree == 2) {
    auto flags = (uint8_t*)rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_FLAGS, 0,
        RTC_FORMAT_UCHAR, sizeof(uint8_t), elements.size());
    if (!flags) return release_unbuilt(geometry);
    for (auto i = 0; i < (int)elements.size(); i++) {
      auto left  = shared && i > 0 && elements[i - 1][1] == elements[i][0];
      auto right = shared && i + 1 < (int)elements.size() &&
                   elements[i + 1][0] == elements[i][1];
      flags[i] = (left ? RTC_CURVE_FLAG_NEIGHBOR_LEFT : 0) |
                 (right ? RTC_CURVE_FLAG_NEIGHBOR_RIGHT : 0);
    }
  }
  return geometry;
}

// Packed strands (pack_fiber_vertices): vertices and first indices, both
// the scene's own memory, read in place.
static RTCGeometry make_packed_curve_geometry(
    RTCDevice device, const shape_data& shape, RTCGeometryType type) {
  auto geometry = rtcNewGeometry(device, type);
  share_packed_vertices(geometry, shape);
  rtcSetSharedGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT,
      shape.fiber_curves.data(), 0, sizeof(int), shape.fiber_curves.size());
  return geometry;
}

// The bend of a segment over its diameter: the control polygon's distance
// from the chord (which bounds the curve's) over twice the largest radius;
// 0 for a straight segment or one with indices out of range.
static float segment_bend_ratio(const shape_data& shape, const vec4i& c) {
  if (!element_in_range(shape, c)) return 0;
  auto p      = [&](int i) { return vertex_position(shape, i); };
  auto chord  = p(c.w) - p(c.x);
  auto along  = dot(chord, chord) > 0 ? normalize(chord) : vec3f{0, 0, 0};
  auto off    = [&](const vec3f& q) {
    auto d = q - p(c.x);
    return length(d - dot(d, along) * along);
  };
  auto bend   = std::max(off(p(c.y)), off(p(c.z)));
  auto radius = 0.0f;
  for (auto k = 0; k < 4; k++) radius = std::max(radius, fiber_vertex(shape, c[k]).w);
  auto ratio = radius > 0 ? bend / (2 * radius) : 0.0f;
  return std::isfinite(ratio) ? ratio : 0.0f;
}

// Pieces of a segment of that ratio: none below the threshold, else as many
// as make the distance small against the radius (it falls with the square of
// the number of pieces: about 3 for a quarter turn of a curl).
static int segment_pieces(float ratio, float threshold, int max_pieces) {
  if (!(ratio > threshold) || !(ratio > 1) || max_pieces <= 1) return 1;
  return std::clamp((int)std::ceil(std::sqrt(ratio)), 2, max_pieces);
}

// Is a Bezier segment a cone: its inner control points on the chord (their
// distance from it bounds the curve's), at fractions a <= b within it (then
// the position along the chord grows with the parameter), and its radius an
// affine function of that position, both within 1e-3 of the largest radius?
// The circles swept across the constant tangent then make the cone between
// the end circles, whatever the parameter's speed.
static bool straight_segment(const shape_data& shape, const vec4i& c, bvh_cone& cone) {
  if (!element_in_range(shape, c)) return false;
  auto q      = curve_control_points(shape, c);
  auto chord  = vec3f(q[3]) - vec3f(q[0]);
  auto length2 = dot(chord, chord);
  auto radius = std::max({q[0].w, q[1].w, q[2].w, q[3].w});
  if (!(length2 > 0) || !(radius > 0) || !std::isfinite(length2) || !std::isfinite(radius))
    return false;
  auto tolerance = 1e-3f * radius;
  auto fraction  = std::array<float, 2>{};
  for (auto k = 1; k <= 2; k++) {
    auto offset = vec3f(q[k]) - vec3f(q[0]);
    auto s      = dot(offset, chord) / length2;
    auto affine = q[0].w + (q[3].w - q[0].w) * s;
    if (!(length(offset - s * chord) <= tolerance) || !(std::abs(q[k].w - affine) <= tolerance))
      return false;
    fraction[k - 1] = s;
  }
  // Rounding may put a control point that coincides with an end a hair
  // outside the chord.
  const auto slack = 1e-5f;
  if (!(fraction[0] >= -slack && fraction[0] <= fraction[1] + slack && fraction[1] <= 1 + slack))
    return false;
  cone.a = std::clamp(fraction[0], 0.0f, 1.0f);
  cone.b = std::clamp(fraction[1], cone.a, 1.0f);
  return true;
}

float cone_bezier_parameter(const bvh_cone& cone, float u) {
  if (std::isnan(u)) return 0;
  u = std::clamp(u, 0.0f, 1.0f);
  // A uniform parameter: the fraction itself (the common middle segment of
  // a Catmull-Rom strand).
  if (std::abs(cone.a - 1.0f / 3) < 1e-6f && std::abs(cone.b - 2.0f / 3) < 1e-6f) return u;
  // The cubic 3 (1 - t)^2 t a + 3 (1 - t) t^2 b + t^3 grows from 0 to 1:
  // Newton's method from t = u (three or four steps), kept inside a bracket
  // that bisection narrows where it would leave it (a flat cubic, with a
  // control point on an end). An error of 1e-6 in the fraction is 1e-6 of
  // the segment along it.
  auto low = 0.0f, high = 1.0f, t = u;
  for (auto iteration = 0; iteration < 30; iteration++) {
    auto w     = 1 - t;
    auto value = 3 * w * t * (w * cone.a + t * cone.b) + t * t * t - u;
    if (std::abs(value) <= 1e-6f) break;
    if (value > 0) high = t; else low = t;
    auto slope = 3 * (w * w * cone.a + 2 * w * t * (cone.b - cone.a) + t * t * (1 - cone.b));
    auto next  = slope > 0 ? t - value / slope : -1.0f;
    t          = next > low && next < high ? next : (low + high) / 2;
    if (high - low < 1e-7f) break;
  }
  return t;
}

// Pieces of each Bezier segment and its straight segments (as cones, when
// asked), or none when nothing is split or straight.
static bvh_curve_pieces make_curve_pieces(
    const shape_data& shape, int max_pieces, float threshold, bool cones) {
  auto pieces = bvh_curve_pieces{};
  max_pieces  = std::min(max_pieces, 4);  // k and n - 1 take 2 bits each
  auto count  = num_curves(shape);
  if (count == 0 || (max_pieces <= 1 && !cones) || count >= (1 << 28)) return pieces;
  auto split = false;
  for (auto element = 0u; element < (uint32_t)count; element++) {
    auto c    = curve_vertices(shape, (int)element);
    auto cone = bvh_cone{element};
    if (cones && straight_segment(shape, c, cone)) {
      pieces.cones.push_back(cone);
      continue;
    }
    auto n = segment_pieces(segment_bend_ratio(shape, c), threshold, max_pieces);
    split  = split || n > 1;
    for (auto k = 0; k < n; k++) pieces.pieces.push_back(element << 4 | k << 2 | (n - 1));
  }
  if (!split && pieces.cones.empty()) return {};
  return pieces;
}

// The cones of a shape's straight segments: a cone's two vertices are its
// segment's ends, shared with the cone before it where the strand goes on.
// Every cone is told that it has neighbours on both sides, so that Embree
// closes none with a disc of its own: the tube stays open, as its Bezier
// would be, and the strand's caps close it. The buffer has a spare vertex
// before and after, should Embree read a neighbour's.
static RTCGeometry make_cone_geometry(
    RTCDevice device, const shape_data& shape, const std::vector<bvh_cone>& cones) {
  auto geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_CONE_LINEAR_CURVE);
  auto count    = cones.size();
  auto indices  = (uint32_t*)rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0,
      RTC_FORMAT_UINT, sizeof(uint32_t), count);
  auto flags    = (uint8_t*)rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_FLAGS, 0,
      RTC_FORMAT_UCHAR, sizeof(uint8_t), count);
  if (!indices || !flags) return release_unbuilt(geometry);
  auto next = (size_t)1;
  for (size_t i = 0; i < count; i++) {
    auto ends   = segment_ends(shape, (int)cones[i].element);
    auto shares = i > 0 && segment_ends(shape, (int)cones[i - 1].element).y == ends.x;
    indices[i]  = (uint32_t)(shares ? next - 1 : next);
    next        = indices[i] + 2;
    flags[i]    = RTC_CURVE_FLAG_NEIGHBOR_LEFT | RTC_CURVE_FLAG_NEIGHBOR_RIGHT;
  }
  auto vertices = (vec4f*)rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0,
      RTC_FORMAT_FLOAT4, sizeof(vec4f), next + 1);
  if (!vertices) return release_unbuilt(geometry);
  for (size_t i = 0; i < count; i++) {
    auto ends                 = segment_ends(shape, (int)cones[i].element);
    vertices[indices[i]]     = fiber_vertex(shape, ends.x);
    vertices[indices[i] + 1] = fiber_vertex(shape, ends.y);
  }
  vertices[0]    = vertices[1];
  vertices[next] = vertices[next - 1];
  return geometry;
}

// Round Bezier curves from the pieces of each segment: the same polynomial
// over [k / n, (k + 1) / n] has control points B(a), B(a) + (b - a) B'(a) / 3,
// B(b) - (b - a) B'(b) / 3, B(b), with the radius as a fourth coordinate.
// A piece starts on the vertex where the one before it ends (the same
// segment's, or a strand's previous segment's: the same vertex index), as
// Embree's consecutive indexing allows: 3 vertices a piece instead of 4.
static RTCGeometry make_curve_pieces_geometry(RTCDevice device, const shape_data& shape,
    const bvh_curve_pieces& pieces, RTCGeometryType type) {
  auto geometry = rtcNewGeometry(device, type);
  auto npieces  = pieces.pieces.size();
  auto indices  = (uint32_t*)rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0,
      RTC_FORMAT_UINT, sizeof(uint32_t), npieces);
  if (!indices) return release_unbuilt(geometry);
  auto valid = [&](const vec4i& c) { return element_in_range(shape, c); };
  auto next  = (size_t)0;
  for (size_t i = 0; i < npieces; i++) {
    auto shares = false;
    if (i > 0) {
      auto element = pieces.pieces[i] >> 4, previous = pieces.pieces[i - 1] >> 4;
      auto  c = curve_vertices(shape, (int)element), before = curve_vertices(shape, (int)previous);
      shares  = valid(c) && (element == previous || (valid(before) && before.w == c.x));
    }
    indices[i] = (uint32_t)(shares ? next - 1 : next);
    next       = indices[i] + 4;
  }
  auto vertices = (vec4f*)rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0,
      RTC_FORMAT_FLOAT4, sizeof(vec4f), next);
  if (!vertices) return release_unbuilt(geometry);
  for (size_t i = 0; i < npieces; i++) {
    auto  c = curve_vertices(shape, (int)(pieces.pieces[i] >> 4));
    auto  k = (int)(pieces.pieces[i] >> 2 & 3);
    auto  n = (int)(pieces.pieces[i] & 3) + 1;
    auto* v = vertices + indices[i];
    if (!valid(c)) {
      for (auto j = 0; j < 4; j++) v[j] = {0, 0, 0, 0};
      continue;
    }
    auto q = curve_control_points(shape, c);
    auto point = [&](float u) {
      auto w = 1 - u;
      return w * w * w * q[0] + 3 * w * w * u * q[1] + 3 * w * u * u * q[2] + u * u * u * q[3];
    };
    auto derivative = [&](float u) {
      auto w = 1 - u;
      return 3 * w * w * (q[1] - q[0]) + 6 * w * u * (q[2] - q[1]) + 3 * u * u * (q[3] - q[2]);
    };
    // A shared first vertex is written again with the same value: the
    // previous piece ended on B(k / n) computed alike, or on the same vertex.
    auto a = (float)k / n, b = (float)(k + 1) / n, d = (b - a) / 3;
    v[0] = k == 0 ? q[0] : point(a);
    v[1] = point(a) + d * derivative(a);
    v[2] = point(b) - d * derivative(b);
    v[3] = k == n - 1 ? q[3] : point(b);
  }
  return geometry;
}

// Strand ends: a segment end that meets no other segment end, packed as
// element << 1 | end (0 at u = 0, 1 at u = 1). Ends meet by position, not
// by vertex index, so strands written with a vertex copy per segment are
// closed at their ends only. Ends of radius zero (tapered tips) and of no
// direction need no cap.
static std::vector<uint32_t> make_fiber_caps(const shape_data& shape) {
  auto caps     = std::vector<uint32_t>{};
  auto add_caps = [&](int count, const auto& element_at) {
    if (count == 0) return;
    auto valid = [&](const auto& element) { return element_in_range(shape, element); };
    // Every segment end with its position's bits (+0 for -0). An end on the
    // same vertex as its neighbour element's (strands) is joined; the others
    // are sorted so that ends at one position are neighbours, and are then
    // looked up at every joint's position: only then is an end alone.
    struct segment_end {
      std::array<uint32_t, 3> position = {};
      uint32_t                packed   = 0;
    };
    auto last = (int)element_at(0).length() - 1;
    auto bits = [&](int vertex) {
      auto position = vertex_position(shape, vertex) + vec3f{0, 0, 0};
      auto result   = std::array<uint32_t, 3>{};
      std::memcpy(result.data(), &position, sizeof(result));
      return result;
    };
    auto joined = [&](int i, int end) {
      auto j = end ? i + 1 : i - 1;
      if (j < 0 || j >= count || !valid(element_at(j))) return false;
      auto a = element_at(i), b = element_at(j);
      return end ? b[0] == a[last] : b[last] == a[0];
    };
    auto ends = std::vector<segment_end>{};
    for (auto i = 0; i < count; i++) {
      auto element = element_at(i);
      if (!valid(element)) continue;
      for (auto end = 0; end < 2; end++)
        if (!joined(i, end))
          ends.push_back({bits(element[end ? last : 0]), (uint32_t)i << 1 | end});
    }
    auto by_position = [](const segment_end& a, const segment_end& b) {
      return a.position < b.position;
    };
    std::sort(ends.begin(), ends.end(), by_position);
    auto alone = std::vector<bool>(ends.size());
    for (size_t k = 0; k < ends.size(); k++)
      alone[k] = (k == 0 || ends[k - 1].position != ends[k].position) &&
                 (k + 1 == ends.size() || ends[k + 1].position != ends[k].position);
    if (!ends.empty()) {
      for (auto i = 0; i < count; i++) {
        if (!valid(element_at(i)) || !joined(i, 1)) continue;
        auto joint = segment_end{bits(element_at(i)[last]), 0};
        auto found = std::lower_bound(ends.begin(), ends.end(), joint, by_position);
        if (found != ends.end() && found->position == joint.position)
          alone[found - ends.begin()] = false;
      }
    }
    for (size_t k = 0; k < ends.size(); k++) {
      if (!alone[k]) continue;
      auto fiber = eval_fiber_end(shape, (int)(ends[k].packed >> 1), (int)(ends[k].packed & 1));
      if (fiber_vertex(shape, fiber.vertex).w <= 0 || length(fiber.outward) == 0) continue;
      caps.push_back(ends[k].packed);
    }
    std::sort(caps.begin(), caps.end());
  };
  // Element counts fit the packing's 31 bits: an int's.
  if (!shape.lines.empty() && shape.lines.size() < (1u << 31)) {
    add_caps((int)shape.lines.size(), [&](int i) { return shape.lines[i]; });
  } else if (num_curves(shape) > 0) {
    add_caps(num_curves(shape), [&](int i) { return curve_vertices(shape, i); });
  }
  return caps;
}

// One disc per strand end, facing out along the fibre's tangent there, of
// the end's radius.
static RTCGeometry make_cap_geometry(
    RTCDevice device, const shape_data& shape, const std::vector<uint32_t>& caps) {
  auto geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_ORIENTED_DISC_POINT);
  auto vertices = (vec4f*)rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0,
      RTC_FORMAT_FLOAT4, sizeof(vec4f), caps.size());
  auto normals  = (vec3f*)rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_NORMAL, 0,
      RTC_FORMAT_FLOAT3, sizeof(vec3f), caps.size());
  if (!vertices || !normals) return release_unbuilt(geometry);
  for (auto i = 0; i < (int)caps.size(); i++) {
    auto fiber  = eval_fiber_end(shape, (int)(caps[i] >> 1), (int)(caps[i] & 1));
    vertices[i] = fiber_vertex(shape, fiber.vertex);
    normals[i]  = normalize(fiber.outward);
  }
  return geometry;
}

static RTCGeometry make_triangle_geometry(RTCDevice device, const shape_data& shape) {
  auto geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto vertices = (vec3f*)rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0,
      RTC_FORMAT_FLOAT3, sizeof(vec3f), shape.positions.size());
  if (!vertices) return release_unbuilt(geometry);
  std::copy(shape.positions.begin(), shape.positions.end(), vertices);
  auto indices = (vec3i*)rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0,
      RTC_FORMAT_UINT3, sizeof(vec3i), shape.triangles.size());
  if (!indices) return release_unbuilt(geometry);
  std::copy(shape.triangles.begin(), shape.triangles.end(), indices);
  return geometry;
}

// A round fibre is seen from outside only (see the header): a hit whose
// geometric normal faces along the ray is the inner side of the wall, met by
// a ray that starts inside the fibre, and is ignored. Normals and directions
// transform so that the sign of their dot product is the same in every
// space, instanced or not.
static bool hit_from_inside(const RTCFilterFunctionNArguments* args, unsigned i) {
  auto inward = RTCRayN_dir_x(args->ray, args->N, i) * RTCHitN_Ng_x(args->hit, args->N, i) +
                RTCRayN_dir_y(args->ray, args->N, i) * RTCHitN_Ng_y(args->hit, args->N, i) +
                RTCRayN_dir_z(args->ray, args->N, i) * RTCHitN_Ng_z(args->hit, args->N, i);
  return inward > 0;
}
static void ignore_hits_from_inside(const RTCFilterFunctionNArguments* args) {
  for (auto i = 0u; i < args->N; i++) {
    if (args->valid[i] == -1 && hit_from_inside(args, i)) args->valid[i] = 0;
  }
}

// Starts fetching a vertex's position and radius, packed or not.
static void prefetch_vertex(const shape_data& shape, int index) {
  if (!shape.fiber_vertices.empty()) {
    __builtin_prefetch(shape.fiber_vertices.data() + index);
  } else {
    __builtin_prefetch(shape.positions.data() + index);
    if (index < (int)shape.radius.size()) __builtin_prefetch(shape.radius.data() + index);
  }
}

// The same for closest hits of an unsplit shape (its geometry's user data),
// which also start fetching the hit segment's end vertices: Embree's leaves
// hold copies of the vertices, so eval_fiber_point's reads would miss the
// cache after the traversal (over half of its time on the peers' hair balls,
// 5 % of a render). The index read here is the one dependent load; the vertex
// fetches then overlap the rest of the traversal. A curve's four vertices span at
// most two cache lines, its first and last vertex's.
static void filter_closest_fiber_hits(const RTCFilterFunctionNArguments* args) {
  auto& shape = *(const shape_data*)args->geometryUserPtr;
  for (auto i = 0u; i < args->N; i++) {
    if (args->valid[i] != -1) continue;
    if (hit_from_inside(args, i)) {
      args->valid[i] = 0;
      continue;
    }
    auto element = (int)RTCHitN_primID(args->hit, args->N, i);
    auto ends    = segment_ends(shape, element);
    prefetch_vertex(shape, ends.x);
    prefetch_vertex(shape, ends.y);
  }
}

// The geometry of a shape, committed; null for an empty shape.
static RTCGeometry make_shape_geometry(RTCDevice device, const shape_data& shape,
    const bvh_curve_pieces& pieces, const bvh_params& params) {
  auto geometry = RTCGeometry{nullptr};
  if (!pieces.cones.empty() && pieces.pieces.empty()) {
    // Every segment is a cone (make_shape_cones).
  } else if (!pieces.pieces.empty()) {
    geometry = make_curve_pieces_geometry(device, shape, pieces,
        params.flat_curves ? RTC_GEOMETRY_TYPE_FLAT_BEZIER_CURVE
                           : RTC_GEOMETRY_TYPE_ROUND_BEZIER_CURVE);
  } else if (!shape.triangles.empty()) {
    geometry = make_triangle_geometry(device, shape);
  } else if (!shape.lines.empty()) {
    geometry = make_curve_geometry(device, shape, shape.lines,
        params.flat_curves ? RTC_GEOMETRY_TYPE_FLAT_LINEAR_CURVE
                           : RTC_GEOMETRY_TYPE_ROUND_LINEAR_CURVE);
  } else if (!shape.curves.empty()) {
    geometry = make_curve_geometry(device, shape, shape.curves,
        params.flat_curves ? RTC_GEOMETRY_TYPE_FLAT_BEZIER_CURVE
                           : RTC_GEOMETRY_TYPE_ROUND_BEZIER_CURVE);
  } else if (!shape.fiber_curves.empty()) {
    geometry = make_packed_curve_geometry(device, shape,
        params.flat_curves ? RTC_GEOMETRY_TYPE_FLAT_BEZIER_CURVE
                           : RTC_GEOMETRY_TYPE_ROUND_BEZIER_CURVE);
  }
  // Round fibres only: a flat fibre faces every ray.
  if (geometry && shape.triangles.empty() && !params.flat_curves) {
    // A split shape's hits are pieces, not its segments.
    if (pieces.pieces.empty()) {
      rtcSetGeometryIntersectFilterFunction(geometry, filter_closest_fiber_hits);
      rtcSetGeometryUserData(geometry, (void*)&shape);
    } else {
      rtcSetGeometryIntersectFilterFunction(geometry, ignore_hits_from_inside);
    }
    rtcSetGeometryOccludedFilterFunction(geometry, ignore_hits_from_inside);
  }
  if (geometry) rtcCommitGeometry(geometry);
  return geometry;
}

// The cones of a shape's straight segments, committed; null when it has none.
// Round fibres only: a flat fibre's segments stay flat Bezier curves.
static RTCGeometry make_shape_cones(
    RTCDevice device, const shape_data& shape, const bvh_curve_pieces& pieces) {
  if (pieces.cones.empty()) return nullptr;
  auto geometry = make_cone_geometry(device, shape, pieces.cones);
  if (!geometry) return nullptr;
  // Where every segment is a cone, a cone's index is its segment's, and
  // closest hits start fetching the segment's vertices as curves' do.
  if (pieces.cones.size() == (size_t)num_curves(shape)) {
    rtcSetGeometryIntersectFilterFunction(geometry, filter_closest_fiber_hits);
    rtcSetGeometryUserData(geometry, (void*)&shape);
  } else {
    rtcSetGeometryIntersectFilterFunction(geometry, ignore_hits_from_inside);
  }
  rtcSetGeometryOccludedFilterFunction(geometry, ignore_hits_from_inside);
  rtcCommitGeometry(geometry);
  return geometry;
}

// The discs closing a shape's strand ends, committed; null when it has none.
// A cap is seen from outside only, round fibres or flat.
static RTCGeometry make_shape_caps(
    RTCDevice device, const shape_data& shape, const std::vector<uint32_t>& caps) {
  if (caps.empty()) return nullptr;
  auto geometry = make_cap_geometry(device, shape, caps);
  if (!geometry) return nullptr;
  rtcSetGeometryIntersectFilterFunction(geometry, ignore_hits_from_inside);
  rtcSetGeometryOccludedFilterFunction(geometry, ignore_hits_from_inside);
  rtcCommitGeometry(geometry);
  return geometry;
}

static void set_scene_quality(RTCScene scene, const bvh_params& params) {
  rtcSetSceneFlags(scene, params.compact ? RTC_SCENE_FLAG_COMPACT : RTC_SCENE_FLAG_NONE);
  rtcSetSceneBuildQuality(scene, params.quality == bvh_quality_type::high
                                     ? RTC_BUILD_QUALITY_HIGH
                                     : params.quality == bvh_quality_type::medium
                                           ? RTC_BUILD_QUALITY_MEDIUM
                                           : RTC_BUILD_QUALITY_LOW);
}

// A shape's own scene, for instancing: the shape is geometry 0, its caps 1,
// its cones 2.
static RTCScene make_shape_scene(RTCDevice device, const shape_data& shape,
    const bvh_curve_pieces& pieces, const std::vector<uint32_t>& caps,
    const bvh_params& params) {
  auto scene = rtcNewScene(device);
  set_scene_quality(scene, params);
  if (auto geometry = make_shape_geometry(device, shape, pieces, params)) {
    rtcAttachGeometryByID(scene, geometry, 0);
    rtcReleaseGeometry(geometry);
  }
  if (auto geometry = make_shape_caps(device, shape, caps)) {
    rtcAttachGeometryByID(scene, geometry, 1);
    rtcReleaseGeometry(geometry);
  }
  if (auto geometry = make_shape_cones(device, shape, pieces)) {
    rtcAttachGeometryByID(scene, geometry, 2);
    rtcReleaseGeometry(geometry);
  }
  rtcCommitScene(scene);
  return scene;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// SCENE BVH
// -----------------------------------------------------------------------------
namespace yocto {

std::string embree_isa(const std::string& config) {
  static const auto names = std::vector<std::string>{"sse2", "sse4.2", "avx", "avx2", "avx512"};
  // The CPU's best, as Embree tests it (AVX2 with FMA and BMI2; AVX-512 as
  // in Skylake-X: F, DQ, CD, BW, VL).
  auto best = 0;
  if (__builtin_cpu_supports("sse4.2")) best = 1;
  if (best == 1 && __builtin_cpu_supports("avx")) best = 2;
  if (best == 2 && __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
      __builtin_cpu_supports("bmi2"))
    best = 3;
  if (best == 3 && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq") &&
      __builtin_cpu_supports("avx512cd") && __builtin_cpu_supports("avx512bw") &&
      __builtin_cpu_supports("avx512vl"))
    best = 4;
  // "key=value" items separated by commas; avx512skx is avx512's old name.
  auto stream = std::istringstream(config);
  for (auto item = std::string{}; std::getline(stream, item, ',');) {
    auto equal = item.find('=');
    if (equal == std::string::npos) continue;
    auto key = item.substr(0, equal), value = item.substr(equal + 1);
    key.erase(0, key.find_first_not_of(' '));
    if (key != "isa" && key != "max_isa") continue;
    if (value.rfind("avx512", 0) == 0) value = "avx512";
    auto found = std::find(names.begin(), names.end(), value);
    if (found != names.end()) best = std::min(best, (int)(found - names.begin()));
  }
  return names[best];
}

std::string embree_version() { return RTC_VERSION_STRING; }

bool make_scene_bvh(scene_bvh& bvh, const scene_data& scene, const bvh_params& params,
    std::string& error) {
  auto start  = std::chrono::steady_clock::now();
  auto errors = std::make_shared<embree_errors>();
  bvh         = {};
  bvh.memory  = std::make_shared<std::atomic<int64_t>>(0);
  auto device = rtcNewDevice(params.embree_config.c_str());
  if (!device) {
    error = "cannot create the Embree device";
    return false;
  }
  // The device owns the error and memory callbacks' targets through captures.
  auto memory     = bvh.memory;
  auto monitor    = std::make_shared<embree_monitor>();
  monitor->memory = memory;
  monitor->limit  = params.max_bytes > 0 ? (int64_t)std::min(params.max_bytes, 9e18) : 0;
  bvh.device      = std::shared_ptr<void>(
      device, [errors, monitor](void* d) { rtcReleaseDevice((RTCDevice)d); });
  rtcSetDeviceErrorFunction(device, embree_error_callback, errors.get());
  rtcSetDeviceMemoryMonitorFunction(device, embree_memory_callback, monitor.get());

  // Instances whose shape is put in the top-level scene directly: the
  // identity frame and a shape no other instance uses.
  auto users = std::vector<int>(scene.shapes.size(), 0);
  for (auto& instance : scene.instances) users[instance.shape]++;
  auto is_flat = [&](const instance_data& instance) {
    return params.flatten && instance.frame == identity3x4f && users[instance.shape] == 1;
  };

  auto release_scene = [device_ref = bvh.device](void* s) { rtcReleaseScene((RTCScene)s); };
  bvh.shapes.resize(scene.shapes.size());
  bvh.pieces.resize(scene.shapes.size());
  bvh.caps.resize(scene.shapes.size());
  // Embree 3's cone intersector takes the ray's direction to be of unit
  // length (its quadratic leaves out the direction's squared length), which
  // an instance's scaling undoes: cones only for shapes whose every instance
  // keeps lengths.
  auto keeps_lengths = std::vector<bool>(scene.shapes.size(), true);
  for (auto& instance : scene.instances) {
    auto& f     = instance.frame;
    auto  near = [](float a, float b) { return std::abs(a - b) < 1e-5f; };
    auto  rigid = near(dot(f.x, f.x), 1) && near(dot(f.y, f.y), 1) && near(dot(f.z, f.z), 1) &&
                 near(dot(f.x, f.y), 0) && near(dot(f.y, f.z), 0) && near(dot(f.z, f.x), 0);
    if (!rigid) keeps_lengths[instance.shape] = false;
  }
  for (auto i = 0; i < (int)scene.shapes.size(); i++) {
    if (users[i] == 0) continue;
    bvh.pieces[i] = make_curve_pieces(scene.shapes[i], params.max_curve_pieces,
        params.curve_piece_threshold,
        params.straight_cones && !params.flat_curves && keeps_lengths[i]);
    bvh.caps[i]   = make_fiber_caps(scene.shapes[i]);
  }
  for (auto& instance : scene.instances) {
    bvh.instance_shapes.push_back(instance.shape);
    if (is_flat(instance) || bvh.shapes[instance.shape]) continue;
    bvh.shapes[instance.shape] = std::shared_ptr<void>(
        make_shape_scene(device, scene.shapes[instance.shape], bvh.pieces[instance.shape],
            bvh.caps[instance.shape], params), release_scene);
  }
  auto top = rtcNewScene(device);
  bvh.scene = std::shared_ptr<void>(top, release_scene);
  set_scene_quality(top, params);
  // Geometry ids are instance indices, flat or not; the caps of a flat
  // instance i are geometry i + the number of instances, its cones i + twice
  // that number.
  auto ninstances = (int)scene.instances.size();
  for (auto i = 0; i < ninstances; i++) {
    auto& instance = scene.instances[i];
    auto  geometry = RTCGeometry{nullptr};
    if (is_flat(instance)) {
      auto& shape = scene.shapes[instance.shape];
      if (auto caps = make_shape_caps(device, shape, bvh.caps[instance.shape])) {
        rtcAttachGeometryByID(top, caps, ninstances + i);
        rtcReleaseGeometry(caps);
      }
      if (auto cones = make_shape_cones(device, shape, bvh.pieces[instance.shape])) {
        rtcAttachGeometryByID(top, cones, 2 * ninstances + i);
        rtcReleaseGeometry(cones);
      }
      geometry = make_shape_geometry(device, shape, bvh.pieces[instance.shape], params);
      if (!geometry) continue;
    } else {
      geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_INSTANCE);
      rtcSetGeometryInstancedScene(geometry, (RTCScene)bvh.shapes[instance.shape].get());
      // frame3f is 12 floats: axes then origin, a column-major 3x4 matrix.
      rtcSetGeometryTransform(geometry, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, &instance.frame);
      rtcCommitGeometry(geometry);
    }
    rtcAttachGeometryByID(top, geometry, i);
    rtcReleaseGeometry(geometry);
  }
  rtcCommitScene(top);
  bvh.peak_memory   = memory->load();
  bvh.build_peak_memory = monitor->peak.load();
  bvh.build_seconds = std::chrono::duration<double>(
      std::chrono::steady_clock::now() - start).count();
  if (monitor->refused || !errors->message.empty()) {
    // Over the budget, or the system (ulimit -v) gave less than it: either
    // way a smaller BVH may still fit.
    auto refused = monitor->refused.load();
    error = refused ? "the BVH needs more than its memory budget of " +
                          std::to_string(monitor->limit) + " bytes"
            : errors->out_of_memory
                ? "the BVH's memory could not be allocated (" + errors->message + ")"
                : errors->message;
    bvh             = {};
    bvh.over_budget = refused || errors->out_of_memory;
    return false;
  }
  return true;
}

// The plan's cost model, measured with Embree 3.13 (AVX2, 2 threads). At
// the peak of its build Embree holds up to 190 bytes a round Bezier curve
// (100 compact): 175-190 (95-98) on a groom of 48,000 segments, 133 (54) on
// the 3.3M-segment curly stand-in of issue 22, so the plan errs on the side
// of the budget. A piece adds 3 vertices, an index and its entry in
// bvh_curve_pieces; its build takes 2.5 CPU-us (8.4 s against 5.0 s on 2 threads for
// 2.67M pieces); splitting a share s of the segments saves about 0.27 s
// CPU-us a ray (1.23 to 1.43 M Embree rays/s, 32 spp at 256x256, for 0.81
// more pieces a segment). So the pieces repay their build when the render
// traces more than 2.5 / 0.27, about 9 rays a segment.
static const double embree_bytes_per_curve         = 190;
static const double embree_compact_bytes_per_curve = 100;
static const double piece_bytes                    = 3 * sizeof(vec4f) + 2 * sizeof(uint32_t);
static const double payback_rays_per_segment       = 9;

bvh_piece_plan plan_curve_pieces(const scene_data& scene, const bvh_params& params,
    double planned_rays, double max_bytes) {
  auto plan       = bvh_piece_plan{};
  plan.max_pieces = std::clamp(params.max_curve_pieces, 1, 4);
  plan.threshold  = params.curve_piece_threshold;
  auto per_curve  = params.compact ? embree_compact_bytes_per_curve : embree_bytes_per_curve;
  // The unsplit BVH of the shapes in use; whether pieces would pay, before
  // their bends are measured.
  auto used = std::vector<bool>(scene.shapes.size(), false);
  for (auto& instance : scene.instances)
    if (instance.shape >= 0 && instance.shape < (int)used.size()) used[instance.shape] = true;
  // Split, a curves shape's segments are all pieces, with vertices of their
  // own instead of the shape's (read in place when packed, else copied).
  auto split_bytes = 0.0;
  for (auto i = 0; i < (int)scene.shapes.size(); i++) {
    auto& shape = scene.shapes[i];
    if (!used[i]) continue;
    auto curves   = (size_t)num_curves(shape);
    auto elements = curves + shape.lines.size() + shape.triangles.size();
    auto copied   = shape.fiber_vertices.empty() ? shape.positions.size() : 0;
    auto bytes = per_curve * elements + sizeof(vec4f) * copied + sizeof(uint32_t) * elements;
    plan.bytes += bytes;
    split_bytes += curves == 0 ? bytes : (per_curve + piece_bytes) * elements;
    plan.segments += (int64_t)curves;
  }
  plan.pieces = plan.segments;
  auto none   = [&]() {
    plan.max_pieces = 1;
    return plan;
  };
  plan.pays = planned_rays >= payback_rays_per_segment * (double)plan.segments;
  if (!plan.pays || plan.max_pieces <= 1) return none();
  // The split segments' bend ratios.
  auto ratios = std::vector<float>{};
  for (auto i = 0; i < (int)scene.shapes.size(); i++) {
    auto& shape = scene.shapes[i];
    if (!used[i] || num_curves(shape) >= (1 << 28)) continue;
    for (auto element = 0; element < num_curves(shape); element++) {
      auto ratio = segment_bend_ratio(shape, curve_vertices(shape, element));
      if (segment_pieces(ratio, plan.threshold, plan.max_pieces) > 1) ratios.push_back(ratio);
    }
  }
  auto extra = [&](float ratio) {
    return segment_pieces(ratio, plan.threshold, plan.max_pieces) - 1;
  };
  auto extra_pieces = (int64_t)0;
  for (auto ratio : ratios) extra_pieces += extra(ratio);
  if (extra_pieces == 0) return none();
  // Within the budget: the most bent segments first.
  auto bytes_per_piece = per_curve + piece_bytes;
  auto room = max_bytes > 0 ? (max_bytes - split_bytes) / bytes_per_piece : 1e30;
  if ((double)extra_pieces > room) {
    std::sort(ratios.begin(), ratios.end(), std::greater<float>{});
    auto fitted = (int64_t)0;
    auto taken  = (size_t)0;
    while (taken < ratios.size() && (double)(fitted + extra(ratios[taken])) <= room)
      fitted += extra(ratios[taken++]);
    // Equal ratios split alike: the threshold excludes the whole tie.
    if (taken < ratios.size()) {
      while (taken > 0 && ratios[taken - 1] == ratios[taken]) fitted -= extra(ratios[--taken]);
      plan.threshold = ratios[taken];
    }
    extra_pieces = fitted;
    if (extra_pieces == 0) return none();
  }
  plan.pieces += extra_pieces;
  plan.bytes = split_bytes + bytes_per_piece * (double)extra_pieces;
  return plan;
}

bool is_traceable_ray(const ray3f& ray) {
  // Embree's FLT_LARGE; comparisons are false for NaN.
  const auto limit = 1.844e18f;
  auto in_range    = [&](const vec3f& v) {
    return std::abs(v.x) <= limit && std::abs(v.y) <= limit && std::abs(v.z) <= limit;
  };
  return in_range(ray.o) && in_range(ray.d) && ray.d != vec3f{0, 0, 0} &&
         !std::isnan(ray.tmin) && !std::isnan(ray.tmax);
}

// A ray for Embree with a direction of unit length (its cones need it; see
// make_scene_bvh) and its range scaled to match; returns the direction's
// length, which converts Embree's distances back to the ray's.
static double init_embree_ray(RTCRay& r, const ray3f& ray) {
  // The rescaling in double: the squared length of a traceable direction
  // neither overflows nor underflows there (in float it may: then it is not
  // near 1 either).
  auto d      = ray.d;
  auto length = 1.0;
  if (std::abs(dot(d, d) - 1) > 1e-6f) {
    length = std::sqrt((double)d.x * d.x + (double)d.y * d.y + (double)d.z * d.z);
    d      = vec3f{(float)(d.x / length), (float)(d.y / length), (float)(d.z / length)};
  }
  auto scaled = [&](float t) { return (float)std::min(t * length, (double)flt_max); };
  r.org_x = ray.o.x;
  r.org_y = ray.o.y;
  r.org_z = ray.o.z;
  r.dir_x = d.x;
  r.dir_y = d.y;
  r.dir_z = d.z;
  r.tnear = length == 1 ? ray.tmin : scaled(ray.tmin);
  r.tfar  = length == 1 ? ray.tmax : scaled(ray.tmax);
  r.time  = 0;
  r.mask  = (unsigned)-1;
  r.id    = 0;
  r.flags = 0;
  return length;
}

scene_intersection intersect_scene_bvh(const scene_bvh& bvh, const ray3f& ray) {
  if (!is_traceable_ray(ray)) return {};
  auto context = RTCIntersectContext{};
  rtcInitIntersectContext(&context);
  auto rayhit = RTCRayHit{};
  auto length = init_embree_ray(rayhit.ray, ray);
  rayhit.hit.geomID    = RTC_INVALID_GEOMETRY_ID;
  rayhit.hit.primID    = RTC_INVALID_GEOMETRY_ID;
  rayhit.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1((RTCScene)bvh.scene.get(), &context, &rayhit);
  if (rayhit.hit.geomID == RTC_INVALID_GEOMETRY_ID) return {};
  auto intersection = scene_intersection{};
  // Flat instances are hit as geometry `instance` of the top-level scene,
  // their caps as `instance` + the number of instances, their cones as
  // `instance` + twice that; instanced shapes as geometry 0 of their scene,
  // their caps as 1, their cones as 2.
  auto ninstances = (unsigned)bvh.instance_shapes.size();
  auto instanced  = rayhit.hit.instID[0] != RTC_INVALID_GEOMETRY_ID;
  auto part = instanced ? rayhit.hit.geomID : rayhit.hit.geomID / ninstances;
  auto cap  = part == 1, cone = part == 2;
  intersection.instance = (int)(instanced ? rayhit.hit.instID[0]
                                          : rayhit.hit.geomID - part * ninstances);
  intersection.element  = (int)rayhit.hit.primID;
  intersection.uv       = {rayhit.hit.u, rayhit.hit.v};
  auto shape            = bvh.instance_shapes[intersection.instance];
  auto& pieces          = bvh.pieces[shape].pieces;
  if (cone) {
    // A straight segment's cone: the segment and its Bezier parameter.
    auto& straight       = bvh.pieces[shape].cones[intersection.element];
    intersection.element = (int)straight.element;
    intersection.uv.x    = cone_bezier_parameter(straight, intersection.uv.x);
  } else if (cap) {
    // A cap: the segment it closes, at the end it closes.
    auto packed          = bvh.caps[shape][intersection.element];
    intersection.element = (int)(packed >> 1);
    intersection.uv      = {(float)(packed & 1), 0};
  } else if (!pieces.empty()) {
    // A piece of a split segment: the segment and its own parameter.
    auto piece           = pieces[intersection.element];
    intersection.element = (int)(piece >> 4);
    intersection.uv.x    = std::min(
        (intersection.uv.x + (float)(piece >> 2 & 3)) / (float)((piece & 3) + 1), 1.0f);
  }
  intersection.distance = length == 1 ? rayhit.ray.tfar : (float)(rayhit.ray.tfar / length);
  intersection.hit      = true;
  return intersection;
}

bool intersect_scene_bvh_any(const scene_bvh& bvh, const ray3f& ray) {
  if (!is_traceable_ray(ray)) return true;
  auto context = RTCIntersectContext{};
  rtcInitIntersectContext(&context);
  auto r = RTCRay{};
  init_embree_ray(r, ray);
  rtcOccluded1((RTCScene)bvh.scene.get(), &context, &r);
  return r.tfar < 0;  // Embree sets tfar to -inf on a hit
}

}  // namespace yocto
