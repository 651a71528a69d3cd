//
// yscene's command line: what its commands share (errors, signals, the memory
// limit, formatting) and, for each command, the options it reads and the
// functions that register and run it. Each command lives in yscene_NAME.cpp;
// yscene.cpp only builds the app and dispatches.
//

#ifndef YSCENE_CLI_H_
#define YSCENE_CLI_H_

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <chrono>
#include <string>
#include <vector>
#include <yocto/yocto_fileio.h>
#include <yocto/yocto_hairgen.h>
#include <yocto/yocto_hairio.h>
#include <yocto/yocto_image.h>
#include <yocto/yocto_pbrtio.h>
#include <yocto/yocto_ply.h>
#include <yocto/yocto_sceneio.h>
#include <yocto/yocto_trace.h>

// -----------------------------------------------------------------------------
// SHARED HELPERS
// -----------------------------------------------------------------------------

// Prints "error: MESSAGE" to stderr and returns the exit status of a failure.
int print_error(const std::string& message);

// Creates the missing directories above an output file before the work that
// fills it, so that a long render or a conversion does not fail at its end.
// The folders made are removed again if the command fails (see main).
bool make_output_directory(const std::string& output, std::string& error);

// SIGTERM, SIGHUP, SIGQUIT and (outside a render) SIGINT end a command with
// nothing of its outputs left: temporaries and the folders it made go, then
// the signal takes its default course.
void handle_fatal_signal(int signal);
void install_signal_handlers();

double      seconds_since(std::chrono::steady_clock::time_point start);
std::string format_count(double count);

// The enum value of a name from its names table (the command line has
// checked that the name is in it).
template <typename Enum, size_t size>
inline Enum enum_from_name(const std::array<std::string, size>& names, const std::string& name) {
  return (Enum)(std::find(names.begin(), names.end(), name) - names.begin());
}

// Every command that loads a scene takes the memory limit of the load; one
// string holds it, whichever command was given.
void add_max_memory_option(CLI::App* command, std::string& max_memory);

// The memory limit of every load, render and merge: --max-memory once main
// has parsed it, the libraries' default otherwise. The one place the app
// keeps it; commands pass it on to the loaders.
extern double memory_limit;

// Import options with the loads' limit set to memory_limit.
yocto::pbrt_params with_memory_limit(yocto::pbrt_params params = {});

// Bytes from --max-memory: a positive number, plain or with a K, M, G or T
// suffix (powers of 1024), e.g. 4G or 1.5G.
bool parse_memory_size(const std::string& text, double& bytes);

// Saves the image of a render or a merge: with its AOV layers (an OpenEXR)
// when it has any, else as save_image does.
bool save_render_image(const std::string& filename, const yocto::texture_data& image,
    const std::vector<yocto::image_layer>& layers, std::string& error, float exposure,
    bool replace = true);

// -----------------------------------------------------------------------------
// RENDER
// -----------------------------------------------------------------------------

struct render_options {
  std::string scene    = "";
  std::string output   = "";
  std::string camera   = "";
  float       exposure = 0;
  bool        flat_curves = false;
  bool        quiet       = false;
  // Benchmark variants and measurements.
  std::string curves      = "native";  // native or lines
  int         segments    = 4;         // line segments per curve with lines
  bool        no_flatten  = false;     // Embree instances even for identity frames
  bool        checkpoints = false;     // save at 1, 2, 4, ... spp
  double      time_budget = 0;         // stop at the first power of two after it
  bool        stats       = false;     // one machine-readable line of figures
  bool        embree_only = false;     // replay the render's rays through Embree
  std::string bvh_quality = "high";    // Embree build quality
  std::string embree_config = "";      // Embree device configuration
  bool        bvh_compact   = false;   // Embree's compact BVH
  int         curve_pieces  = 4;       // most exact pieces of a bent Bezier segment
  float       curve_piece_threshold = 1;  // bend over diameter that splits (the plan's)
  bool        straight_cones = true;   // straight Bezier segments as Embree cones
  std::string sample_range  = "";      // A:B: render these samples as a part
};

// What `render` reads: its options, the tracer's parameters and the names of
// the tracer's enums (turned into values after parsing).
struct render_command {
  render_options      options  = {};
  yocto::trace_params params   = {};
  std::string         sampler  = "path";
  std::string         lights   = "automatic";
  std::string         sequence = "global-sobol";
};

CLI::App* add_render_command(CLI::App& app, render_command& command, std::string& max_memory);
// `cli` is the parsed subcommand: it tells which options were given.
int run_render(const render_command& command, const CLI::App& cli);

// -----------------------------------------------------------------------------
// SERVE
// -----------------------------------------------------------------------------

struct serve_options {
  std::string scene      = "";
  std::string host       = "127.0.0.1";
  int         port       = 8000;
  std::string camera     = "";
  std::string output_dir = ".";
};

// What `serve` reads: its options and the tracer's parameters.
struct serve_command {
  serve_options       options = {};
  yocto::trace_params params  = {};
};

CLI::App* add_serve_command(CLI::App& app, serve_command& command, std::string& max_memory);
int       run_serve(const serve_command& command, const CLI::App& cli);

// -----------------------------------------------------------------------------
// MERGE
// -----------------------------------------------------------------------------

struct merge_options {
  std::vector<std::string> parts    = {};
  std::string              output   = "";
  float                    exposure = 0;
  bool                     part     = false;  // write a part (the union), not an image
  bool                     quiet    = false;
};

CLI::App* add_merge_command(CLI::App& app, merge_options& options, std::string& max_memory);
int       run_merge(const merge_options& options);

// -----------------------------------------------------------------------------
// INFO
// -----------------------------------------------------------------------------

// What `info` says about a scene: the counts, and every camera, material
// (with the values the renderer uses), environment and light, as text or
// as json.
struct info_options {
  std::string scene = "";
  bool        json  = false;
};

CLI::App* add_info_command(CLI::App& app, info_options& options, std::string& max_memory);
int       run_info(const info_options& options);

// -----------------------------------------------------------------------------
// CONVERT
// -----------------------------------------------------------------------------

struct convert_options {
  std::string        input  = "";
  std::string        output = "";
  std::string        curves = "native";  // native or lines
  yocto::pbrt_params params = {};
  bool               quiet  = false;
  // USD input (scripts/usd_to_yocto.py): the time code read ("" for the
  // default time), a json scene whose hair material grooms take and the
  // width of curves that author none ("" for the converter's 0.01).
  std::string usd_time      = "";
  std::string hair_material = "";
  std::string usd_width     = "";
};

CLI::App* add_convert_command(CLI::App& app, convert_options& options, std::string& max_memory);
int       run_convert(const convert_options& options);

// A temporary folder that removes itself, with everything in it, when it goes.
struct temporary_folder {
  std::string path = "";
  temporary_folder() = default;
  temporary_folder(const temporary_folder&) = delete;
  temporary_folder& operator=(const temporary_folder&) = delete;
  ~temporary_folder();
};

// USD stages (.usd, .usda, .usdc, .usdz), read by Pixar's usd-core through
// scripts/usd_to_yocto.py, the one path of convert, render and info.
bool is_usd_file(const std::string& filename);
// Converts a USD stage into a json scene in a new temporary `folder`
// (FOLDER/scene.json). On failure `child_failed` says that the converter has
// printed its error already; otherwise `error` says what went wrong.
bool convert_usd_stage(const std::string& input, const convert_options& options,
    temporary_folder& folder, std::string& error, bool& child_failed);
// Loads what load_any_scene reads (within params' memory limit), or a USD
// stage converted with `usd`'s options and loaded (checked as any json
// scene): the loader of convert and info. On failure `child_failed` says
// that the converter has printed its error already.
bool load_cli_scene(const std::string& filename, yocto::scene_data& scene,
    const convert_options& usd, const yocto::pbrt_params& params, std::string& error,
    bool& child_failed);

// -----------------------------------------------------------------------------
// HAIR GENERATOR
// -----------------------------------------------------------------------------

struct hair_options {
  std::string output       = "";
  std::string style        = "straight";
  std::string fit_camera   = "";     // scene whose first camera places the strands
  float       fit_fraction = 0.75f;  // of the image the strands span
  float       fit_distance = 0;      // 0: where the camera sees them now
  bool        quiet        = false;  // nothing printed on success
};

// What `hair` reads: its options, the generator's parameters and the
// material's, one list of values per row of hair_parameters (empty if not
// given).
struct hair_command {
  hair_options                    options = {};
  yocto::hair_style_params        params  = {};
  std::vector<std::vector<float>> values  = {};
};

CLI::App* add_hair_command(CLI::App& app, hair_command& command, std::string& max_memory);
int       run_hair(const hair_command& command);

#endif
