//
// # Yocto/Bvh: ray queries on Embree
//
// One Embree geometry per shape (triangles, round linear curves for lines,
// round cubic Bezier curves for curves, or ray-facing flat curves on request;
// fibre shapes also get one of discs that close their strands' ends) in a
// top-level scene. An instance with the identity frame whose shape no
// other instance uses is put in the top-level scene directly (one traversal
// level less, the common case of hair scenes); others are Embree instances of
// a per-shape scene. Bent Bezier segments are split into exact pieces for
// Embree (bvh_params::max_curve_pieces); straight ones are given to it as
// the truncated cones they are (bvh_params::straight_cones). Intersections
// return the instance, the element and Embree's parametric coordinates
// (mapped back from a piece or a cone to its segment); fiber geometry at a
// hit (tangent,
// radius, signed offset h) is computed by `eval_fiber_point` in yocto_scene.
//
// Rays and fibres. A round fibre (line or curve) is a tube seen from outside
// only: a ray that starts inside a fibre passes its wall without a hit (an
// Embree filter drops hits whose geometric normal faces along the ray), for
// closest hits and shadow rays alike. The hair model accounts for the whole
// passage of light through the fibre it hit, so the renderer never needs the
// inside; and fibres of generated or simulated grooms overlap their
// neighbours, which real hair does not: a ray leaving one fibre often starts
// inside another, whose inner wall must not trap it. A ray leaving a fibre
// starts on the circle of 1.01 radius around the axis, on the side of its
// direction (spawn_fiber_ray in yocto_scene), so it is outside its own fibre
// and moves away from it. Flat fibres face every ray and have no inside.
//
// Caps. A strand is closed at each end (a segment end at whose position no
// other segment ends) by a flat disc across its tangent there, of the end's
// radius, seen from outside only; a hit on it is a hit on the end segment at
// u = 0 or 1, shaded like any hit on the fibre. Without it Embree's round
// curves are open at the ends and miss rays along the axis, so a fibre seen
// end-on showed a hole. Straight segments given as cones are as open (Embree
// is told that every cone has neighbours, so it puts no disc of its own at
// either end) and closed by the same discs. Lines also keep the half sphere
// Embree puts around a line's end; ends of radius 0 (tapered tips) have no cap.
//

#ifndef YOCTO_BVH_H_
#define YOCTO_BVH_H_

#include <array>
#include <atomic>
#include <memory>
#include <string>
#include <vector>

#include "yocto_scene.h"

// -----------------------------------------------------------------------------
// BVH
// -----------------------------------------------------------------------------
namespace yocto {

enum struct bvh_quality_type { low, medium, high };
inline const auto bvh_quality_names = std::array<std::string, 3>{"low", "medium", "high"};

struct bvh_params {
  bool flat_curves = false;  // ray-facing flat curves instead of round tubes
  bool compact     = false;  // Embree's compact layout: less memory, a bit slower
  bool flatten     = true;   // identity instances of unshared shapes without instancing
  bvh_quality_type quality = bvh_quality_type::high;  // Embree's build quality
  // Bent Bezier segments are given to Embree as up to this many exact pieces
  // (the same curve; 1 to 4), fewer for straighter ones, none for straight
  // ones: Embree's bounds of a bent segment are loose, and rays test it often.
  int max_curve_pieces = 4;
  // A segment is split when the bend of its control polygon over its
  // diameter exceeds this (1: every segment the pieces tighten; larger: only
  // the most bent; plan_curve_pieces chooses it from a budget).
  float curve_piece_threshold = 1;
  // A round Bezier segment is the sweep of a circle across its tangent: where
  // it runs along a straight line and its radius is an affine function of the
  // position along it (within 1e-3 of its radius), that tube is a truncated
  // cone, which Embree intersects in closed form instead of by subdivision
  // (the same hits, faster rays; see make_curve_pieces).
  bool straight_cones = true;
  std::string embree_config = "";  // Embree device configuration, e.g. "verbose=2"
  // Most bytes Embree may hold at once (0: no limit): an allocation beyond it
  // is refused and the build fails with over_budget set (the caller may try
  // again with fewer curve pieces or the compact layout).
  double max_bytes = 0;
};

// A straight segment given to Embree as a cone from its first vertex to its
// last: along the chord, its inner control points lie at the fractions a and
// b (1/3 and 2/3 for a uniform parameter), which map a hit's position on the
// cone back to the Bezier's parameter.
struct bvh_cone {
  uint32_t element = 0;
  float    a = 1.0f / 3, b = 2.0f / 3;
};

// Where the pieces of a curves shape come from: piece i is the k-th of n
// equal parts of segment e, packed as e << 4 | k << 2 | (n - 1) (one load
// per hit); `cones` are its straight segments, which no piece covers. Both
// empty when nothing is split or straight (the shape's segments are given
// as they are); pieces alone empty when every segment is a cone.
struct bvh_curve_pieces {
  std::vector<uint32_t> pieces = {};
  std::vector<bvh_cone> cones  = {};
};

// The Bezier parameter of a cone's hit at u, the fraction of the chord where
// the hit's circle crosses the axis: the inverse of the cubic that maps the
// parameter to that fraction (monotone for a cone).
float cone_bezier_parameter(const bvh_cone& cone, float u);

// Embree handles are shared pointers so that the struct copies and frees
// itself; `memory` is what Embree holds for this scene, in bytes,
// `peak_memory` what it held after the build and `build_peak_memory` the
// most it held at once (the build's temporaries too).
struct scene_bvh {
  std::shared_ptr<void>              device = nullptr;
  std::shared_ptr<void>              scene  = nullptr;
  std::vector<std::shared_ptr<void>> shapes = {};
  std::vector<bvh_curve_pieces>      pieces = {};           // per shape
  // Per shape, its strand ends closed by discs: element << 1 | end (u = end).
  std::vector<std::vector<uint32_t>> caps = {};
  std::vector<int>                   instance_shapes = {};  // per instance
  std::shared_ptr<std::atomic<int64_t>> memory      = nullptr;
  int64_t                                 peak_memory = 0;
  int64_t                                 build_peak_memory = 0;
  double                                  build_seconds = 0;
  // Failed on max_bytes, or on memory the system refused (ulimit -v).
  bool                                    over_budget = false;
};

struct scene_intersection {
  int   instance = -1;
  int   element  = -1;
  vec2f uv       = {0, 0};
  float distance = 0;
  bool  hit      = false;
};

// Builds the BVH; returns false with a message on an Embree error. The
// index buffers of strands are the scene's own curves and lines, not copies,
// and so are the vertex buffers of strands packed by pack_fiber_vertices:
// keep the scene alive and unchanged while its BVH is used.
bool make_scene_bvh(scene_bvh& bvh, const scene_data& scene, const bvh_params& params,
    std::string& error);

// How far to split bent segments, decided before the build from the scene
// (how many segments, how bent), the rays the render will trace and the
// memory the BVH may take. Pieces cost memory and build time per piece and
// save ray time in proportion to the share of segments split, so they pay
// only when the render traces enough rays per segment (a few spp on a
// large groom do not repay the build); and they are given to the most bent
// segments first, as far as `max_bytes` allows (0: no limit).
struct bvh_piece_plan {
  int     max_pieces = 1;     // 1: no segment is split
  float   threshold  = 1;     // bvh_params::curve_piece_threshold
  int64_t segments   = 0;     // Bezier segments of the scene's used shapes
  int64_t pieces     = 0;     // what Embree gets for them under the plan
  double  bytes      = 0;     // estimated BVH bytes under the plan
  bool    pays       = true;  // do the planned rays repay the pieces' build?
};
bvh_piece_plan plan_curve_pieces(const scene_data& scene, const bvh_params& params,
    double planned_rays, double max_bytes);

// The instruction set of Embree's kernels for a device configuration: the
// best one this CPU has (sse2, sse4.2, avx, avx2, avx512), capped by an
// `isa=` or `max_isa=` in `config` (Embree's own keys). Kernels of different
// instruction sets round curve hits differently, so renders that must agree
// bit for bit (the parts of one image) record and compare it.
std::string embree_isa(const std::string& config);

// The version of Embree this library was built with, e.g. "3.13.5".
std::string embree_version();

// Can Embree trace the ray? Origin and direction components within Embree's
// range (it asserts beyond 1.844e18), a non-zero direction, tmin and tmax not
// NaN. The queries below treat any other ray as a miss (as occluded for
// shadow rays): validate_scene keeps scenes in range, this keeps a ray made
// non-finite by round-off from aborting the program.
bool is_traceable_ray(const ray3f& ray);

// Closest hit along the ray within [tmin, tmax].
scene_intersection intersect_scene_bvh(const scene_bvh& bvh, const ray3f& ray);
// Is anything hit within [tmin, tmax]? (shadow rays)
bool intersect_scene_bvh_any(const scene_bvh& bvh, const ray3f& ray);

}  // namespace yocto

#endif
