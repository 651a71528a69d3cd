//
// yscene serve: look-dev in a browser. Loads the scene and builds the BVH
// once, then serves a progressive render whose hair materials, lights and
// camera the page edits (libs/yocto/yocto_serve.h), until Ctrl-C.
//

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <thread>
#include <yocto/yocto_serve.h>

#include "yscene_cli.h"

using namespace yocto;

// -----------------------------------------------------------------------------
// SERVE
// -----------------------------------------------------------------------------

static std::atomic<bool> serve_stop = false;
static void handle_serve_signal(int) { serve_stop = true; }

CLI::App* add_serve_command(CLI::App& app, serve_command& command, std::string& max_memory) {
  auto& options = command.options;
  auto& params  = command.params;
  // A look-dev render goes on to 1024 samples unless the scene or --samples says.
  params.samples = 1024;
  auto  serve   = app.add_subcommand("serve",
      "look-dev in a browser: a progressive render whose hair, lights and camera a web "
      "page edits (prints its URL, with an access token)");
  serve->add_option("scene", options.scene, "scene: json, pbrt or hair, as render reads")
      ->required();
  serve->add_option("--port", options.port, "port to listen on (0: any free one)")
      ->check(CLI::Range(0, 65535));
  serve->add_option("--host", options.host,
      "address to listen on (127.0.0.1: this machine only; 0.0.0.0 opens it to the network)");
  serve->add_option("--resolution,-r", params.resolution, "largest image side in pixels");
  serve->add_option("--samples,-s", params.samples,
      "samples per pixel after which the render idles (until the next edit)");
  serve->add_option("--threads,-t", params.threads, "render threads (0 = all cores)");
  serve->add_option("--camera", options.camera, "camera name to start with");
  serve->add_option("--output-dir", options.output_dir,
      "folder where Save writes the image (exr, png) and the edited scene (json)");
  serve->add_flag("--aovs", params.aovs, "also render the AOV layers, to look at one at a time");
  add_max_memory_option(serve, max_memory);
  return serve;
}

int run_serve(const serve_command& command, const CLI::App& cli) {
  auto& options             = command.options;
  auto  settings            = render_session_params{};
  settings.scene            = options.scene;
  settings.camera           = options.camera;
  settings.samples_given    = cli.count("--samples") > 0;
  settings.resolution_given = cli.count("--resolution") > 0;
  settings.max_memory       = memory_limit;
  auto session = std::make_unique<render_session>();
  auto error   = std::string{};
  if (!load_render_session(*session, settings, command.params, error))
    return print_error(error);
  auto warnings = std::vector<std::string>{};
  auto built    = build_render_session(*session, error, &warnings);
  for (auto& warning : warnings) std::fprintf(stderr, "warning: %s\n", warning.c_str());
  if (!built) return print_error(error);
  auto params       = serve_params{};
  params.host       = options.host;
  params.port       = options.port;
  params.output_dir = options.output_dir;
  auto server       = scene_server{};
  serve_stop        = false;
  auto previous_int  = std::signal(SIGINT, handle_serve_signal);
  auto previous_term = std::signal(SIGTERM, handle_serve_signal);
  if (!start_scene_server(server, std::move(session), params, error)) return print_error(error);
  std::printf("serving %s at %s\n", options.scene.c_str(), server.url.c_str());
  std::fflush(stdout);
  while (!serve_stop) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  std::fprintf(stderr, "stopping\n");
  stop_scene_server(server);
  std::signal(SIGINT, previous_int);
  std::signal(SIGTERM, previous_term);
  return 0;
}
