//
// Implementation of Yocto/Serve.
//

#include "yocto_serve.h"

#include <httplib.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <mutex>
#include <nlohmann/json.hpp>
#include <random>
#include <thread>

#include "yocto_image.h"
#include "yocto_sceneio.h"
#include "yocto_serve_assets.h"  // generated from apps/serve/ (scripts/embed_files.cmake)

// -----------------------------------------------------------------------------
// SERVER STATE
// -----------------------------------------------------------------------------
namespace yocto {

using json = nlohmann::json;

// What orbit, pan and zoom turn around, per camera.
struct serve_view {
  vec3f target = {0, 0, 0};
  vec3f up     = {0, 1, 0};
};

// The scene as the edits left it: the render thread copies it in before
// it restarts.
struct serve_edits {
  std::vector<material_data>      materials     = {};
  std::vector<environment_data>   environments  = {};
  std::vector<distant_light_data> lights        = {};
  std::vector<camera_data>        cameras       = {};
  std::vector<serve_view>         views         = {};
  std::vector<float>              environment_strengths = {};
  std::vector<float>              light_strengths       = {};
  int                             camera        = 0;
};

// A published image: the render's estimate after a pass, or a preview.
struct serve_frame {
  texture_data             image      = {};
  std::vector<image_layer> layers     = {};
  int                      number     = 0;
  int                      generation = 0;
  int                      samples    = 0;  // 0 for a preview
  bool                     preview    = false;
  double                   seconds    = 0;
  double                   samples_per_second = 0;
};

// A save asked for by a request, done by the render thread between passes.
struct serve_save {
  float       exposure = 0;
  bool        done     = false;
  bool        ok       = false;
  json        result   = {};
  std::string error    = "";
};

struct serve_state {
  serve_params   params  = {};
  std::unique_ptr<render_session> session = {};  // the render thread's once started
  // As loaded: what strengths scale and resets return to.
  std::vector<environment_data>   loaded_environments = {};
  std::vector<distant_light_data> loaded_lights       = {};
  std::vector<camera_data>        loaded_cameras      = {};
  std::vector<serve_view>         loaded_views        = {};
  std::vector<std::string>        layer_names         = {};
  std::string                     scene_stem          = "";
  // Copies for the request threads (a save reorders the scene's cameras).
  std::vector<std::string>        camera_names        = {};
  std::vector<std::string>        material_names      = {};
  std::vector<std::string>        environment_names   = {};
  std::string                     scene_filename      = "";
  int                             width = 0, height = 0, target_samples = 0;
  httplib::Server                 http                = {};
  std::thread                     http_thread         = {};
  std::thread                     render_thread       = {};
  // Shared between the threads, under the mutex; `cancel` stops a pass.
  std::mutex                               mutex      = {};
  std::condition_variable                  wake       = {};  // the render thread
  std::condition_variable                  saved      = {};  // requests waiting for a save
  std::condition_variable                  published  = {};  // requests waiting for a frame
  std::atomic<bool>                        cancel     = false;
  bool                                     stopping   = false;
  serve_edits                              edits      = {};
  int                                      generation = 0;
  std::shared_ptr<const serve_frame>       frame      = nullptr;
  int                                      frames     = 0;
  std::deque<std::shared_ptr<serve_save>>  saves      = {};
};

}  // namespace yocto

// -----------------------------------------------------------------------------
// RENDER THREAD
// -----------------------------------------------------------------------------
namespace yocto {

static void publish_frame(serve_state& state, std::shared_ptr<serve_frame> frame) {
  auto lock     = std::lock_guard{state.mutex};
  frame->number = ++state.frames;
  state.frame   = std::move(frame);
  state.published.notify_all();
}

static void publish_render(serve_state& state, int generation) {
  auto& session = *state.session;
  auto  frame   = std::make_shared<serve_frame>();
  frame->image      = get_image(session.state);
  frame->layers     = get_aov_layers(session.state);
  frame->generation = generation;
  frame->samples    = session.state.samples;
  frame->seconds    = session.seconds;
  frame->samples_per_second =
      session.seconds > 0 ? (double)session.state.width * session.state.height *
                                session.state.samples / session.seconds
                          : 0;
  publish_frame(state, std::move(frame));
}

// One sample per pixel at `scale` of the image's resolution, with the last
// roulette threshold (so no pilot runs); false if cancelled.
static bool render_preview(serve_state& state, float scale, float roulette_threshold,
    texture_data& image, double& seconds) {
  auto& session     = *state.session;
  auto  params      = session.params;
  params.resolution = std::clamp((int)std::lround(params.resolution * scale), 8,
      params.resolution);
  params.samples    = 1;
  params.adaptive   = trace_adaptive_type::off;
  params.split      = 1;
  params.allocation = false;
  params.aovs       = false;
  if (roulette_threshold > 0) params.roulette_threshold = roulette_threshold;
  auto start   = std::chrono::steady_clock::now();
  auto preview = trace_state{};
  init_trace_state(preview, session.scene, params);
  if (!trace_samples(preview, session.scene, session.bvh, session.context, params, 1,
          &state.cancel))
    return false;
  image   = get_image(preview);
  seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return true;
}

// The first frames after an edit, before its first full pass: previews of
// one sample at a fraction of the pixels (the page scales them up), the
// first taking about params.preview_seconds, each next one with four times
// the pixels while that stays under a quarter of a full pass. An edit can
// change a sample's cost several times over (light hair scatters longer),
// so a probe of a few pixels measures it first, not the last pass.
static void publish_previews(serve_state& state, int generation, float roulette_threshold) {
  auto& session = *state.session;
  auto  pixels  = (double)session.state.width * session.state.height;
  auto  probe   = texture_data{};
  auto  seconds = 0.0;
  auto  probe_scale = std::min(1.0f, 32.0f / session.params.resolution);
  if (!render_preview(state, probe_scale, roulette_threshold, probe, seconds)) return;
  auto full_pass = seconds * pixels / ((double)probe.width * probe.height);
  auto scale     = (float)std::sqrt(state.params.preview_seconds / full_pass);
  for (; scale <= 0.5f; scale *= 2) {
    auto image = texture_data{};
    if (!render_preview(state, std::max(scale, probe_scale), roulette_threshold, image, seconds))
      return;
    auto frame        = std::make_shared<serve_frame>();
    frame->image      = std::move(image);
    frame->generation = generation;
    frame->preview    = true;
    publish_frame(state, std::move(frame));
  }
}

// NAME-NNNN.{exr,png,json} in the output folder, the first number none of
// whose files exists; the image, then the scene with the current camera
// first and the render's settings, so that `yscene render` of the json
// renders this picture. Each file is written whole or not at all.
static bool save_served_render(
    serve_state& state, float exposure, json& result, std::string& error) {
  auto& session = *state.session;
  auto  base    = std::string{};
  for (auto number = 1; number < 100000; number++) {
    char suffix[32];
    std::snprintf(suffix, sizeof(suffix), "-%04d", number);
    base        = path_join(state.params.output_dir, state.scene_stem + suffix);
    auto exists = false;
    for (auto extension : {".exr", ".png", ".json"})
      exists = exists || std::filesystem::exists(base + extension);
    if (!exists) break;
  }
  // The three files or none: a failure removes what this save wrote.
  auto written = std::vector<std::string>{};
  auto failed  = [&] {
    auto ignored = std::error_code{};
    for (auto& filename : written) std::filesystem::remove(filename, ignored);
    return false;
  };
  auto image  = get_image(session.state);
  auto layers = get_aov_layers(session.state);
  if (!save_image_layers(base + ".exr", image, layers, error, false)) return failed();
  written.push_back(base + ".exr");
  if (!save_image(base + ".png", image, error, exposure, false)) return failed();
  written.push_back(base + ".png");
  auto& scene    = session.scene;
  auto  camera   = session.params.camera;
  auto  settings = scene.settings;
  std::swap(scene.cameras[0], scene.cameras[camera]);
  if (!scene.camera_names.empty()) std::swap(scene.camera_names[0], scene.camera_names[camera]);
  scene.settings = {session.params.resolution, session.state.samples, session.params.bounces};
  auto ok = save_scene(base + ".json", scene, error);
  scene.settings = settings;
  std::swap(scene.cameras[0], scene.cameras[camera]);
  if (!scene.camera_names.empty()) std::swap(scene.camera_names[0], scene.camera_names[camera]);
  if (!ok) return failed();
  result = {{"image", base + ".exr"}, {"png", base + ".png"}, {"scene", base + ".json"},
      {"samples", session.state.samples}};
  return true;
}

static void run_render_loop(serve_state& state) {
  auto& session       = *state.session;
  auto  applied       = -1;
  while (true) {
    auto lock = std::unique_lock{state.mutex};
    state.wake.wait(lock, [&] {
      return state.stopping || state.generation != applied || !state.saves.empty() ||
             !is_render_session_done(session);
    });
    if (state.stopping) break;
    if (state.generation != applied) {
      auto& edits                 = state.edits;
      session.scene.materials      = edits.materials;
      session.scene.environments   = edits.environments;
      session.scene.distant_lights = edits.lights;
      session.scene.cameras        = edits.cameras;
      session.params.camera        = edits.camera;
      applied                      = state.generation;
      state.cancel                 = false;
      lock.unlock();
      auto threshold = session.state.roulette_threshold;
      restart_render_session(session);
      publish_previews(state, applied, threshold);
      continue;
    }
    if (!state.saves.empty() && session.state.samples > 0) {
      auto saves = std::move(state.saves);
      state.saves.clear();
      lock.unlock();
      for (auto& save : saves) save->ok = save_served_render(state, save->exposure,
                                    save->result, save->error);
      lock.lock();
      for (auto& save : saves) save->done = true;
      state.saved.notify_all();
      continue;
    }
    lock.unlock();
    if (is_render_session_done(session)) continue;
    if (!render_session_pass(session, &state.cancel)) continue;  // an edit came
    publish_render(state, applied);
  }
  // Requests still waiting for a save learn that it will not come.
  auto lock = std::lock_guard{state.mutex};
  for (auto& save : state.saves) save->done = true, save->error = "the server is stopping";
  state.saves.clear();
  state.saved.notify_all();
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// REQUESTS
// -----------------------------------------------------------------------------
namespace yocto {

static void send_json(httplib::Response& response, int status, const json& body) {
  response.status = status;
  response.set_header("Cache-Control", "no-store");
  response.set_content(body.dump(), "application/json");
}

static void send_error(httplib::Response& response, int status, const std::string& message,
    const std::string& field = "") {
  auto body = json{{"error", message}};
  if (!field.empty()) body["field"] = field;
  send_json(response, status, body);
}

// Whether the request carries the token, compared in constant time.
static bool has_token(const serve_state& state, const httplib::Request& request) {
  auto token = request.has_header("X-Token") ? request.get_header_value("X-Token")
                                             : request.get_param_value("token");
  auto& expected = state.params.token;
  if (token.size() != expected.size()) return false;
  auto difference = 0;
  for (size_t i = 0; i < token.size(); i++) difference |= token[i] ^ expected[i];
  return difference == 0;
}

// A request's edit, checked before anything changes: `fail` names the field.
struct serve_request_error {
  std::string message = "";
  std::string field   = "";
};

static bool fail(serve_request_error& error, const std::string& field, const std::string& message) {
  error = {message, field};
  return false;
}

static bool check_keys(const json& body, std::initializer_list<const char*> keys,
    serve_request_error& error) {
  for (auto& [key, value] : body.items()) {
    auto known = false;
    for (auto name : keys) known = known || key == name;
    if (!known) return fail(error, key, "unknown field " + key);
  }
  return true;
}

static bool read_number(const json& body, const char* field, float min, float max,
    float& value, serve_request_error& error) {
  auto& item = body.at(field);
  if (!item.is_number() || !std::isfinite(item.get<double>()))
    return fail(error, field, std::string(field) + ": expected a finite number");
  auto number = item.get<double>();
  if (number < min || number > max)
    return fail(error, field,
        std::string(field) + ": " + json(number).dump() + " is not in [" + json(min).dump() +
            ", " + json(max).dump() + "]");
  value = (float)number;
  return true;
}

static bool read_vector(const json& body, const char* field, int size, float limit,
    std::vector<float>& values, serve_request_error& error) {
  auto& item = body.at(field);
  if (!item.is_array() || (int)item.size() != size)
    return fail(error, field, std::string(field) + ": expected " + std::to_string(size) +
                                  " numbers");
  values.clear();
  for (auto& number : item) {
    if (!number.is_number() || !std::isfinite(number.get<double>()) ||
        std::abs(number.get<double>()) > limit)
      return fail(error, field, std::string(field) + ": expected finite numbers of at most " +
                                    json(limit).dump() + " in magnitude");
    values.push_back(number.get<float>());
  }
  return true;
}

// An element by name (in names) or index, of `count`.
static bool read_element(const json& body, const char* field, const std::vector<std::string>& names,
    int count, int& index, serve_request_error& error) {
  if (!body.contains(field)) return fail(error, field, std::string("missing field ") + field);
  auto& item = body.at(field);
  if (item.is_number_integer()) {
    index = item.get<int>();
  } else if (item.is_string()) {
    auto found = std::find(names.begin(), names.end(), item.get<std::string>());
    index      = found == names.end() ? -1 : (int)(found - names.begin());
  } else {
    return fail(error, field, std::string(field) + ": expected a name or an index");
  }
  if (index < 0 || index >= count)
    return fail(error, field, std::string(field) + ": no " + field + " " + item.dump());
  return true;
}

static bool edit_material(serve_state& state, serve_edits& edits, const json& body,
    serve_request_error& error) {
  auto index = 0;
  if (!check_keys(body, {"material", "parameter", "value"}, error) ||
      !read_element(body, "material", state.material_names, (int)edits.materials.size(),
          index, error))
    return false;
  auto& material = edits.materials[index];
  if (material.type != material_type::hair)
    return fail(error, "material", "material " + body.at("material").dump() + " is not hair");
  if (!body.contains("parameter") || !body.at("parameter").is_string())
    return fail(error, "parameter", "parameter: expected a hair parameter's name");
  auto name      = body.at("parameter").get<std::string>();
  auto parameter = find_hair_parameter(name);
  if (!parameter) return fail(error, "parameter", "unknown hair parameter " + name);
  if (!body.contains("value")) return fail(error, "value", "missing field value");
  auto value = vec3f{0};
  if (parameter->kind == hair_parameter_kind::number) {
    auto number = 0.0f;
    if (!read_number(body, "value", -flt_max, flt_max, number, error)) return false;
    value = vec3f{number};
  } else {
    auto values = std::vector<float>{};
    if (!read_vector(body, "value", 3, flt_max, values, error)) return false;
    value = {values[0], values[1], values[2]};
  }
  if (!is_hair_parameter_valid(*parameter, value))
    return fail(error, "value", name + " " + format_hair_parameter_value(*parameter, value) +
                                    " is not " + format_hair_parameter_range(*parameter));
  auto hair = material.hair;
  set_hair_parameter(hair, *parameter, value);
  // A pigment set here is the one the user sees: those that take
  // precedence over it (sigma_a, then colour, then melanin) are cleared.
  auto key = std::string(parameter->name);
  if (key == "eumelanin" || key == "pheomelanin") hair.has_sigma_a = hair.has_color = false;
  if (key == "color") hair.has_sigma_a = false;
  if (key == "tip_eumelanin" || key == "tip_pheomelanin")
    hair.has_tip_sigma_a = hair.has_tip_color = false;
  if (key == "tip_color") hair.has_tip_sigma_a = false;
  auto message = std::string{};
  if (!check_hair_material(hair, message)) return fail(error, "value", message);
  material.hair = hair;
  return true;
}

static bool edit_environment(serve_state& state, serve_edits& edits, const json& body,
    serve_request_error& error) {
  auto index = 0;
  if (!check_keys(body, {"environment", "strength"}, error) ||
      !read_element(body, "environment", state.environment_names,
          (int)edits.environments.size(), index, error))
    return false;
  if (!body.contains("strength")) return fail(error, "strength", "missing field strength");
  auto strength = 0.0f;
  if (!read_number(body, "strength", 0, 1000, strength, error)) return false;
  edits.environments[index].emission   = state.loaded_environments[index].emission * strength;
  edits.environment_strengths[index] = strength;
  return true;
}

static bool edit_light(serve_state& state, serve_edits& edits, const json& body,
    serve_request_error& error) {
  auto index = 0;
  if (!check_keys(body, {"light", "strength", "direction"}, error) ||
      !read_element(body, "light", {}, (int)edits.lights.size(), index, error))
    return false;
  if (!body.contains("strength") && !body.contains("direction"))
    return fail(error, "strength", "expected strength, direction or both");
  auto light = edits.lights[index];
  if (body.contains("strength")) {
    auto strength = 0.0f;
    if (!read_number(body, "strength", 0, 1000, strength, error)) return false;
    light.emission                = state.loaded_lights[index].emission * strength;
    edits.light_strengths[index] = strength;
  }
  if (body.contains("direction")) {
    auto values = std::vector<float>{};
    if (!read_vector(body, "direction", 3, 1e6f, values, error)) return false;
    auto direction = vec3f{values[0], values[1], values[2]};
    if (!(length(direction) > 1e-6f))
      return fail(error, "direction", "direction: expected a non-zero vector");
    light.direction = normalize(direction);
  }
  edits.lights[index] = light;
  return true;
}

// Orbit (yaw about the view's up, pitch about the camera's right), pan and
// zoom around the view's target; the frame is rebuilt looking at it.
static bool edit_camera(serve_state& state, serve_edits& edits, const json& body,
    serve_request_error& error) {
  if (!check_keys(body, {"camera", "orbit", "pan", "zoom", "reset"}, error)) return false;
  if (body.contains("camera")) {
    auto index = 0;
    if (!read_element(body, "camera", state.camera_names, (int)edits.cameras.size(), index,
            error))
      return false;
    edits.camera         = index;
    edits.cameras[index] = state.loaded_cameras[index];
    edits.views[index]   = state.loaded_views[index];
  }
  auto  index  = edits.camera;
  auto& camera = edits.cameras[index];
  auto& view   = edits.views[index];
  if (body.contains("reset")) {
    if (!body.at("reset").is_boolean())
      return fail(error, "reset", "reset: expected true or false");
    if (body.at("reset").get<bool>()) {
      camera = state.loaded_cameras[index];
      view   = state.loaded_views[index];
    }
  }
  auto values = std::vector<float>{};
  auto eye    = camera.frame.o;
  auto offset = eye - view.target;
  if (body.contains("orbit")) {
    if (!read_vector(body, "orbit", 2, 10, values, error)) return false;
    offset = transform_vector(rotation_frame(view.up, -values[0]), offset);
    // Pitch, kept off the poles so that the frame stays defined.
    auto distance = length(offset);
    auto angle    = std::acos(std::clamp(dot(offset / distance, view.up), -1.0f, 1.0f));
    auto pitch    = std::clamp(values[1], angle - pif + 0.02f, angle - 0.02f);
    auto right    = normalize(cross(view.up, offset));
    offset        = transform_vector(rotation_frame(right, -pitch), offset);
  }
  if (body.contains("zoom")) {
    auto zoom = 1.0f;
    if (!read_number(body, "zoom", 0.01f, 100, zoom, error)) return false;
    offset *= zoom;
  }
  if (!(length(offset) > 1e-6f) || !isfinite(offset))
    return fail(error, "zoom", "the camera would reach its target");
  auto frame = lookat_frame(view.target + offset, view.target, view.up);
  if (body.contains("pan")) {
    if (!read_vector(body, "pan", 2, 10, values, error)) return false;
    // The view's height at the target, for the fractions of it.
    auto height = length(offset) * camera_film_size(camera).y / camera.lens;
    auto move   = (-values[0] * frame.x + values[1] * frame.y) * height;
    view.target += move;
    frame.o += move;
  }
  if (body.contains("orbit") || body.contains("zoom") || body.contains("pan"))
    camera.frame = frame;
  return true;
}

static json describe_parameter(const hair_material& hair, const hair_parameter& parameter) {
  auto value = get_hair_parameter(hair, parameter);
  auto item  = json{{"name", parameter.name},
      {"kind", parameter.kind == hair_parameter_kind::number ? "number" : "rgb"},
      {"group", parameter.group == hair_parameter_group::pigment
                    ? "pigment"
                    : (parameter.group == hair_parameter_group::fiber ? "fiber" : "variation")},
      {"min", parameter.min}, {"min_open", parameter.min_open},
      {"max_open", parameter.max_open}, {"unit", parameter.unit}, {"doc", parameter.doc},
      {"set", is_hair_parameter_set(hair, parameter)}};
  item["max"] = parameter.max == flt_max ? json(nullptr) : json(parameter.max);
  if (parameter.kind == hair_parameter_kind::number) item["value"] = value.x;
  else item["value"] = {value.x, value.y, value.z};
  return item;
}

// The state the page shows, under the mutex.
static json describe_state(const serve_state& state) {
  auto& edits = state.edits;
  auto  body  = json{{"scene", state.scene_filename}, {"generation", state.generation},
      {"target_samples", state.target_samples}, {"camera", edits.camera},
      {"output_dir", state.params.output_dir}, {"layers", state.layer_names},
      {"width", state.width}, {"height", state.height}};
  auto& frame = state.frame;
  body["frame"]              = frame ? frame->number : 0;
  body["frame_generation"]   = frame ? frame->generation : -1;
  body["preview"]            = frame ? frame->preview : false;
  body["samples"]            = frame ? frame->samples : 0;
  body["seconds"]            = frame ? frame->seconds : 0;
  body["samples_per_second"] = frame ? frame->samples_per_second : 0;
  auto cameras = json::array();
  for (auto i = 0; i < (int)edits.cameras.size(); i++)
    cameras.push_back(i < (int)state.camera_names.size() ? state.camera_names[i]
                                                         : "camera " + std::to_string(i));
  body["cameras"] = cameras;
  auto materials  = json::array();
  for (auto i = 0; i < (int)edits.materials.size(); i++) {
    auto& material = edits.materials[i];
    if (material.type != material_type::hair) continue;
    auto parameters = json::array();
    for (auto& parameter : hair_parameters)
      parameters.push_back(describe_parameter(material.hair, parameter));
    materials.push_back({{"name", i < (int)state.material_names.size() ? state.material_names[i]
                                                                        : std::to_string(i)},
        {"index", i}, {"parameters", parameters}});
  }
  body["materials"] = materials;
  auto environments = json::array();
  for (auto i = 0; i < (int)edits.environments.size(); i++)
    environments.push_back({{"name", i < (int)state.environment_names.size()
                                         ? state.environment_names[i]
                                         : std::to_string(i)},
        {"index", i}, {"strength", edits.environment_strengths[i]}});
  body["environments"] = environments;
  auto lights          = json::array();
  for (auto i = 0; i < (int)edits.lights.size(); i++) {
    auto& direction = edits.lights[i].direction;
    lights.push_back({{"index", i}, {"strength", edits.light_strengths[i]},
        {"direction", {direction.x, direction.y, direction.z}}});
  }
  body["lights"] = lights;
  return body;
}

// Narkowicz's fit of the ACES filmic curve (2015), on exposed linear values.
static float filmic_curve(float x) {
  x *= 0.6f;
  return std::clamp((x * (2.51f * x + 0.03f)) / (x * (2.43f * x + 0.59f) + 0.14f), 0.0f, 1.0f);
}

// The frame's layer as an image to look at: colour as rendered, normals and
// tangents from [-1, 1] to [0, 1], one-channel layers as grey.
static bool frame_layer_image(const serve_state& state, const serve_frame& frame,
    const std::string& layer, texture_data& image) {
  if (layer == "color") return image = frame.image, true;
  // A preview renders colour alone: shown for any layer until the next pass.
  if (frame.preview && std::find(state.layer_names.begin(), state.layer_names.end(), layer) !=
                           state.layer_names.end())
    return image = frame.image, true;
  for (auto& found : frame.layers) {
    if (found.name != layer) continue;
    auto channels = (int)found.channels.size();
    image         = texture_data{frame.image.width, frame.image.height, {}};
    image.pixels.resize(frame.image.pixels.size());
    auto signed_values = layer == "normal" || layer == "tangent";
    for (size_t i = 0; i < image.pixels.size(); i++) {
      auto value = vec3f{0};
      for (auto c = 0; c < 3; c++) value[c] = found.pixels[i * channels + std::min(c, channels - 1)];
      image.pixels[i] = signed_values ? value * 0.5f + 0.5f : value;
    }
    return true;
  }
  return false;
}

static void handle_frame(serve_state& state, const httplib::Request& request,
    httplib::Response& response) {
  auto layer = request.has_param("layer") ? request.get_param_value("layer") : "color";
  auto view  = request.has_param("view") ? request.get_param_value("view") : "standard";
  auto exposure = 0.0f;
  if (request.has_param("exposure")) {
    auto text   = request.get_param_value("exposure");
    auto end    = (char*)nullptr;
    auto number = std::strtod(text.c_str(), &end);
    if (text.empty() || *end != 0 || !std::isfinite(number) || std::abs(number) > 20)
      return send_error(response, 400, "exposure: expected a number of stops in [-20, 20]",
          "exposure");
    exposure = (float)number;
  }
  if (view != "standard" && view != "filmic")
    return send_error(response, 400, "view: expected standard or filmic", "view");
  auto frame = std::shared_ptr<const serve_frame>{};
  {
    auto lock = std::lock_guard{state.mutex};
    frame     = state.frame;
  }
  if (!frame) return send_error(response, 503, "no frame yet");
  auto image = texture_data{};
  if (!frame_layer_image(state, *frame, layer, image))
    return send_error(response, 400, "layer: no layer " + layer, "layer");
  auto scale = std::exp2(exposure);
  for (auto& pixel : image.pixels) {
    pixel *= scale;
    if (view == "filmic")
      pixel = {filmic_curve(pixel.x), filmic_curve(pixel.y), filmic_curve(pixel.z)};
  }
  auto data  = std::string{};
  auto error = std::string{};
  if (!encode_image("frame.png", image, data, error, 0))
    return send_error(response, 500, error);
  response.set_header("Cache-Control", "no-store");
  response.set_header("X-Frame", std::to_string(frame->number));
  response.set_header("X-Generation", std::to_string(frame->generation));
  response.set_header("X-Samples", std::to_string(frame->samples));
  response.set_content(data, "image/png");
}

using serve_edit = bool (*)(serve_state&, serve_edits&, const json&, serve_request_error&);

// Parses and checks an edit on a copy of the edits; only a valid one
// replaces them, cancels the pass in flight and wakes the render thread.
static void handle_edit(serve_state& state, serve_edit edit, const httplib::Request& request,
    httplib::Response& response) {
  auto body = json::parse(request.body, nullptr, false);
  if (body.is_discarded()) return send_error(response, 400, "malformed JSON body");
  if (!body.is_object()) return send_error(response, 400, "expected a JSON object");
  auto lock   = std::lock_guard{state.mutex};
  auto edits  = state.edits;
  auto error  = serve_request_error{};
  if (!edit(state, edits, body, error))
    return send_error(response, 400, error.message, error.field);
  state.edits = std::move(edits);
  state.generation++;
  state.cancel = true;
  state.wake.notify_all();
  send_json(response, 200, {{"generation", state.generation}});
}

static void handle_save(serve_state& state, const httplib::Request& request,
    httplib::Response& response) {
  auto save = std::make_shared<serve_save>();
  if (!request.body.empty()) {
    auto body = json::parse(request.body, nullptr, false);
    if (body.is_discarded()) return send_error(response, 400, "malformed JSON body");
    if (!body.is_object()) return send_error(response, 400, "expected a JSON object");
    auto error = serve_request_error{};
    if (!check_keys(body, {"exposure"}, error) ||
        (body.contains("exposure") &&
            !read_number(body, "exposure", -20, 20, save->exposure, error)))
      return send_error(response, 400, error.message, error.field);
  }
  auto lock = std::unique_lock{state.mutex};
  if (state.stopping) return send_error(response, 503, "the server is stopping");
  state.saves.push_back(save);
  state.wake.notify_all();
  state.saved.wait(lock, [&] { return save->done; });
  if (!save->ok)
    return send_error(response, 500, save->error.empty() ? "not saved" : save->error);
  send_json(response, 200, save->result);
}

static const char* asset_type(const std::string& name) {
  if (name.size() > 5 && name.substr(name.size() - 5) == ".html") return "text/html; charset=utf-8";
  if (name.size() > 3 && name.substr(name.size() - 3) == ".js")
    return "text/javascript; charset=utf-8";
  if (name.size() > 4 && name.substr(name.size() - 4) == ".css") return "text/css; charset=utf-8";
  return "application/octet-stream";
}

static void add_routes(serve_state& state) {
  auto& http = state.http;
  // The token and the body's size before anything else (the body is not
  // read yet); no CORS header is ever set, so other origins cannot read.
  http.set_pre_routing_handler([&state](const httplib::Request& request,
                                   httplib::Response& response) {
    if (!has_token(state, request)) {
      send_error(response, 403, "missing or wrong token (open the URL the server printed)");
      return httplib::Server::HandlerResponse::Handled;
    }
    auto length = request.get_header_value("Content-Length");
    auto digits = length.find_first_not_of("0123456789") == std::string::npos;
    if (!length.empty() && (!digits || length.size() > 9 || std::stoll(length) > serve_body_limit)) {
      send_error(response, 400,
          "body over " + std::to_string(serve_body_limit) + " bytes", "body");
      return httplib::Server::HandlerResponse::Handled;
    }
    return httplib::Server::HandlerResponse::Unhandled;
  });
  http.set_payload_max_length(serve_body_limit);
  // A response goes out as several writes: without this, Nagle's algorithm
  // holds the last one for the client's delayed ACK (about 40 ms a request).
  http.set_tcp_nodelay(true);
  for (auto& asset : serve_assets) {
    auto name = std::string(asset.name);
    auto path = name == "index.html" ? std::string("/") : "/" + name;
    http.Get(path, [asset, name](const httplib::Request&, httplib::Response& response) {
      response.set_header("Cache-Control", "no-store");
      response.set_content((const char*)asset.data, asset.size, asset_type(name));
    });
  }
  // With ?after=N, a long poll: answers once a frame after frame N is
  // published (or after serve_poll_milliseconds), so that a page sees a
  // new frame when it comes rather than at its next poll.
  http.Get("/api/state", [&state](const httplib::Request& request, httplib::Response& response) {
    auto after = -1;
    if (request.has_param("after")) {
      auto text   = request.get_param_value("after");
      auto end    = (char*)nullptr;
      auto number = std::strtoll(text.c_str(), &end, 10);
      if (text.empty() || *end != 0 || number < 0 || number > INT_MAX)
        return send_error(response, 400, "after: expected a frame number", "after");
      after = (int)number;
    }
    auto lock = std::unique_lock{state.mutex};
    if (after >= 0)
      state.published.wait_for(lock, std::chrono::milliseconds(serve_poll_milliseconds),
          [&] { return state.stopping || state.frames > after; });
    send_json(response, 200, describe_state(state));
  });
  http.Get("/api/frame.png", [&state](const httplib::Request& request,
                                 httplib::Response& response) {
    handle_frame(state, request, response);
  });
  auto edits = std::vector<std::pair<std::string, serve_edit>>{{"/api/material", edit_material},
      {"/api/environment", edit_environment}, {"/api/light", edit_light},
      {"/api/camera", edit_camera}};
  for (auto& [path, edit] : edits) {
    http.Post(path, [&state, edit = edit](const httplib::Request& request,
                        httplib::Response& response) {
      handle_edit(state, edit, request, response);
    });
  }
  http.Post("/api/save", [&state](const httplib::Request& request, httplib::Response& response) {
    handle_save(state, request, response);
  });
  http.set_error_handler([](const httplib::Request&, httplib::Response& response) {
    if (response.body.empty())
      send_error(response, response.status, "HTTP " + std::to_string(response.status));
  });
  http.set_exception_handler(
      [](const httplib::Request&, httplib::Response& response, std::exception_ptr) {
        send_error(response, 500, "internal error");
      });
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// SCENE SERVER
// -----------------------------------------------------------------------------
namespace yocto {

static std::string make_token() {
  auto device = std::random_device{};
  auto token  = std::string{};
  for (auto i = 0; i < 4; i++) {
    char buffer[16];
    std::snprintf(buffer, sizeof(buffer), "%08x", (unsigned)device());
    token += buffer;
  }
  return token;
}

// Where orbits turn: the point on the view axis nearest the scene's centre
// (or half the scene's size ahead when that lies behind), the camera's up.
static serve_view make_view(const camera_data& camera, const bbox3f& bounds) {
  auto forward  = -camera.frame.z;
  auto extent   = empty(bounds) ? 1.0f : std::max(length(size(bounds)), 1e-3f);
  auto distance = empty(bounds) ? 1.0f : dot(center(bounds) - camera.frame.o, forward);
  if (!(distance > extent * 1e-3f)) distance = extent / 2;
  return {camera.frame.o + forward * distance, camera.frame.y};
}

bool start_scene_server(scene_server& server, std::unique_ptr<render_session> session,
    const serve_params& params, std::string& error) {
  auto state     = std::make_shared<serve_state>();
  state->params  = params;
  if (state->params.token.empty()) state->params.token = make_token();
  state->session = std::move(session);
  if (!state->session) {
    error = "no render session to serve";
    return false;
  }
  auto& scene    = state->session->scene;
  auto  ec       = std::error_code{};
  if (!std::filesystem::is_directory(params.output_dir, ec)) {
    error = params.output_dir + ": no such folder (--output-dir)";
    return false;
  }
  auto stem = std::filesystem::path(state->session->settings.scene).stem().string();
  state->scene_stem = stem.empty() ? "scene" : stem;
  state->loaded_environments = scene.environments;
  state->loaded_lights       = scene.distant_lights;
  state->loaded_cameras      = scene.cameras;
  auto bounds                = compute_bounds(scene);
  for (auto& camera : scene.cameras) state->loaded_views.push_back(make_view(camera, bounds));
  state->camera_names      = scene.camera_names;
  state->material_names    = scene.material_names;
  state->environment_names = scene.environment_names;
  state->scene_filename    = state->session->settings.scene;
  state->width             = state->session->state.width;
  state->height            = state->session->state.height;
  state->target_samples    = state->session->count;
  state->layer_names = {"color"};
  for (auto& layer : get_aov_layers(state->session->state))
    state->layer_names.push_back(layer.name);
  auto& edits        = state->edits;
  edits.materials    = scene.materials;
  edits.environments = scene.environments;
  edits.lights       = scene.distant_lights;
  edits.cameras      = scene.cameras;
  edits.views        = state->loaded_views;
  edits.camera       = state->session->params.camera;
  edits.environment_strengths.assign(scene.environments.size(), 1);
  edits.light_strengths.assign(scene.distant_lights.size(), 1);
  add_routes(*state);
  state->http.set_keep_alive_timeout(1);
  auto port = params.port == 0 ? state->http.bind_to_any_port(params.host)
                               : (state->http.bind_to_port(params.host, params.port)
                                         ? params.port
                                         : -1);
  if (port <= 0) {
    error = "cannot listen on " + params.host + ":" + std::to_string(params.port) +
            " (in use, or not an address of this machine)";
    return false;
  }
  server.port  = port;
  server.token = state->params.token;
  server.url   = "http://" + params.host + ":" + std::to_string(port) + "/?token=" +
               server.token;
  server.state = state;
  state->render_thread = std::thread([state] { run_render_loop(*state); });
  state->http_thread   = std::thread([state] { state->http.listen_after_bind(); });
  return true;
}

void stop_scene_server(scene_server& server) {
  auto state = server.state;
  if (!state) return;
  {
    auto lock       = std::lock_guard{state->mutex};
    state->stopping = true;
    state->cancel   = true;
    state->wake.notify_all();
    state->published.notify_all();
  }
  if (state->render_thread.joinable()) state->render_thread.join();
  state->http.stop();
  if (state->http_thread.joinable()) state->http_thread.join();
  server.state = nullptr;
}

}  // namespace yocto
