//
// # Yocto/HairGen: procedural hair scenes
//
// Deterministic hair geometry in the styles of the thesis's scenes (straight
// hair on a head-sized sphere, curly hair, a lock of curls, a block of
// fibers) and of a benchmark fur ball, as chains of cubic Bezier segments
// with a radius tapering towards the tip, and complete scenes around them
// with a procedural sky (a plain white environment for the fur ball). The
// head styles use the frame of Cem Yuksel's hair models (y up, scalp centred
// near (0, 10, 0), about 12 units across), the lock of curls that of
// Bitterli's hair-curl model (hanging from (-4, 11.5, 0)), the block pbrt's
// hair block (the unit cube, fibers along z): stand-ins land where real scene
// files' cameras expect the real geometry. The fur ball's short straight
// strands grow from the unit sphere at the origin.
//

#ifndef YOCTO_HAIRGEN_H_
#define YOCTO_HAIRGEN_H_

#include <array>
#include <string>

#include "yocto_scene.h"

// -----------------------------------------------------------------------------
// HAIR GENERATION
// -----------------------------------------------------------------------------
namespace yocto {

enum struct hair_style { straight, curly, curls, block, fur };
inline const auto hair_style_names = std::array<std::string, 5>{
    "straight", "curly", "curls", "block", "fur"};

struct hair_style_params {
  hair_style style    = hair_style::straight;
  int        strands  = 10000;
  int        segments = 0;  // Bezier segments per strand, 0 for the style's default
  float      radius   = 0;  // root radius, 0 for the style's default
  uint64_t   seed     = 7;
};

// Bezier segments per strand: the parameter, or the style's default.
int hair_strand_segments(const hair_style_params& params);

// Strands as a curves shape: each strand is a chain of cubic Bezier segments
// sharing end points, radius tapering from the root to 20% at the tip.
// strands * (3 segments + 1) control points.
shape_data make_hair_strands(const hair_style_params& params);

// The sphere the head styles grow from (center and radius).
inline const vec3f hair_head_center = {0, 10, 0};
inline const float hair_head_radius = 5.2f;

// A procedural sky (equirectangular, y up): a blue gradient above a warm
// horizon, a darker ground and a soft sun, linear radiance around 1.
texture_data make_sky_texture(int width, int height, const vec3f& sun_direction);

// A complete scene: camera, sky environment, the strands with a hair
// material, and the head sphere (head styles), a sphere beside the block, or
// the grey unit sphere under the fur in a white environment (fur). The hair
// material is `hair`, every parameter as given (variation included), but for
// the curls' four locks, which take their own melanin instead of its pigment.
scene_data make_hair_scene(const hair_style_params& params, const hair_material& hair);

}  // namespace yocto

// -----------------------------------------------------------------------------
// PLACEMENT FOR A CAMERA
// -----------------------------------------------------------------------------
namespace yocto {

// The frame (a uniform scale about the strands' bounding box centre, then a
// translation) that places strands where a camera looks: the box centre on
// the view axis at `distance`, scaled so that the silhouette of the control
// points spans `fraction` of the image along its tighter axis. A distance of
// 0 takes the depth at which the camera sees the box centre where it is, if
// that is in front of the camera, else the camera's focus distance. Returns
// the identity for empty strands or a fraction or camera it cannot fit.
// Orthographic cameras are treated as perspective ones: stand-ins are for
// pbrt's and Yocto's perspective hair scenes.
frame3f fit_hair_to_camera(const camera_data& camera, const shape_data& strands,
    float fraction, float distance = 0);

// Moves strands by a frame: positions transformed, radii scaled by the
// frame's scale (so fibers keep their thickness relative to the hair).
void transform_hair_strands(shape_data& strands, const frame3f& frame);

}  // namespace yocto

#endif
