//
// # Yocto/Hair: a physically based hair scattering model
//
// The model of Pharr, The Implementation of a Hair Scattering Model (2016),
// built on d'Eon et al., An Energy-Conserving Hair Reflectance Model (EGSR
// 2011) and Chiang et al., A Practical and Controllable Hair and Fur Model for
// Production Path Tracing (EGSR 2016). Depends on the math header alone.
//

#ifndef YOCTO_HAIR_H_
#define YOCTO_HAIR_H_

#include <yocto/yocto_math.h>

// -----------------------------------------------------------------------------
// HAIR MATERIAL AND BSDF
// -----------------------------------------------------------------------------
namespace yocto {

// What the json and pbrt loaders fill. Precedence as pbrt: sigma_a if given,
// else color if given, else melanin.
struct hair_material {
  vec3f sigma_a     = {0, 0, 0};  // used if has_sigma_a
  vec3f color       = {0, 0, 0};  // used if has_color
  float eumelanin   = 1.3f;
  float pheomelanin = 0.0f;
  float beta_m      = 0.3f;  // longitudinal roughness in [0, 1]
  float beta_n      = 0.3f;  // azimuthal roughness in [0, 1]
  float alpha       = 2.0f;  // scale tilt in degrees
  float eta         = 1.55f;
  bool  has_sigma_a = false;
  bool  has_color   = false;
};

// Everything precomputed for one hit (filled by eval_hair_brdf).
struct hair_brdf;

}  // namespace yocto

#endif
