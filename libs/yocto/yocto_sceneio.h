//
// # Yocto/SceneIO: json scenes, and any scene by its extension
//
// Json scenes in Yocto/GL's 4.2 layout (arrays and integer references) and the
// older 4.0 layout (objects keyed by name), with their shapes as PLY files
// (yocto_ply) and textures as images (yocto_image); and the one loader of
// every scene format: json, pbrt (yocto_pbrtio) and Cem Yuksel's .hair models
// (yocto_hairio). Every function returns false with a one-line message
// naming the file and the element or line on bad input. A scene is saved
// all or nothing: its files are written to temporary names and renamed when
// all are complete.
//

#ifndef YOCTO_SCENEIO_H_
#define YOCTO_SCENEIO_H_

#include <string>
#include <vector>

#include "yocto_fileio.h"
#include "yocto_hairio.h"
#include "yocto_image.h"
#include "yocto_pbrtio.h"
#include "yocto_ply.h"
#include "yocto_scene.h"

// -----------------------------------------------------------------------------
// SCENES
// -----------------------------------------------------------------------------
namespace yocto {

// Loads a json scene with its shapes and textures. Warnings (unknown keys)
// are appended to `warnings` if given, printed to stderr otherwise.
//
// Groups: `cameras`, `environments`, `textures`, `shapes`, `materials`,
// `instances` (or `objects`, as 4.0 calls them), plus `asset` (copyright),
// `distant_lights` and `settings` (resolution, samples, bounces). Each group
// is an array (4.2: integer references, `uri` files relative to the json)
// or an object keyed by name (4.0: references by name; a shape or texture
// named but not listed is found at shapes/NAME.ply or
// textures/NAME.{hdr,exr,png,jpg,jpeg,pfm}); layouts may mix per group.
// Frames are 12 numbers (x, y, z axes, then origin) or a 9-number `lookat`
// (from, to, up); a camera placed by lookat focuses on `to`.
//
// Material types: matte, glossy, hair; other Yocto types map to the nearest
// with a warning (plastic, metal, reflective, gltfpbr -> glossy; transparent,
// refractive, glass, subsurface, volumetric -> matte); anything else is an
// error. A material without `type` is hair if it has a hair key (a name or
// alias of hair_parameters other than color) or if the instances that use it
// all have fiber (lines or curves) shapes; otherwise matte. Hair keys are the
// rows of hair_parameters (yocto_scene.h: names, aliases such as betaM,
// ranges, defaults), color going into hair.color; a key's has_ flag is set
// when it is given; one pigment given makes the other 0. Keys a type does
// not use are dropped with a warning (e.g. roughness on hair), so a loaded
// material holds defaults in the fields its type ignores. Bad values, wrong types, out-of-range
// references, missing files and hair on a triangle mesh are errors.
// Each file is loaded once: shape (texture) elements that name the same file,
// the path resolved, become one shape (texture) that their users share, named
// after the first of them. The files' sizes and their sum are checked against
// max_memory.
bool load_scene(const std::string& filename, scene_data& scene, std::string& error,
    std::vector<std::string>* warnings = nullptr, double max_memory = default_memory_limit());

// Saves a json scene (4.2 layout) with shapes as PLY files under shapes/ and
// textures as float EXR under textures/, next to the json, named after the
// elements (made safe and unique). Each material writes the keys its type
// uses (hair: optional keys when given, variation keys when away from their
// defaults, the others always), so load_scene(save_scene(scene)) gives back
// every field that has a meaning. The scene is validated first; on failure the files this call
// created are removed.
bool save_scene(const std::string& filename, const scene_data& scene,
    std::string& error, bool ascii_shapes = false);

}  // namespace yocto

// -----------------------------------------------------------------------------
// ANY SCENE
// -----------------------------------------------------------------------------
namespace yocto {

// Loads a scene by its extension: .pbrt or .gz with load_pbrt_scene, .hair
// with load_hair_scene (params' curves_as_lines and segments), anything else
// as json with load_scene; each within params.max_memory.
bool load_any_scene(const std::string& filename, scene_data& scene, std::string& error,
    const pbrt_params& params = {});

}  // namespace yocto

#endif
