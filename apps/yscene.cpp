//
// yscene: render, inspect and convert hair scenes.
//
// Each command lives in yscene_NAME.cpp over yscene_cli.h; here is only the
// app that registers them and runs the one given.
//

#include <cstdio>
#include <exception>
#include <new>

#include "yscene_cli.h"

using namespace yocto;

// -----------------------------------------------------------------------------
// MAIN
// -----------------------------------------------------------------------------

static int run_main(int argc, const char** argv) {
  auto app = CLI::App{"yscene: render, inspect and convert hair scenes"};
  app.require_subcommand(1);

  // Registered in the order the help lists them; one memory limit for all.
  auto max_memory   = std::string{};
  auto render_cmd   = render_command{};
  auto info_opts    = info_options{};
  auto merge_opts   = merge_options{};
  auto convert_opts = convert_options{};
  auto hair_cmd     = hair_command{};
  auto serve_cmd    = serve_command{};
  auto render       = add_render_command(app, render_cmd, max_memory);
  auto info         = add_info_command(app, info_opts, max_memory);
  auto merge        = add_merge_command(app, merge_opts, max_memory);
  auto convert      = add_convert_command(app, convert_opts, max_memory);
  auto hair         = add_hair_command(app, hair_cmd, max_memory);
  auto serve        = add_serve_command(app, serve_cmd, max_memory);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // Help exits 0; every command-line error exits 1 as other errors do.
    auto code = app.exit(e);
    return code == 0 ? 0 : 1;
  }
  if (!max_memory.empty() && !parse_memory_size(max_memory, memory_limit))
    return print_error("--max-memory " + max_memory +
                       ": expected a number of bytes, optionally with a K, M or G suffix (e.g. 4G)");

  if (render->parsed()) return run_render(render_cmd, *render);
  if (merge->parsed()) return run_merge(merge_opts);
  if (info->parsed()) return run_info(info_opts);
  if (hair->parsed()) return run_hair(hair_cmd);
  if (convert->parsed()) return run_convert(convert_opts);
  if (serve->parsed()) return run_serve(serve_cmd, *serve);
  return 1;
}

// Whatever escapes (a huge scene's allocation) is one error line, not an
// abort. A command that fails leaves none of the folders it made.
int main(int argc, const char** argv) {
  install_signal_handlers();
  auto code = 1;
  try {
    code = run_main(argc, argv);
  } catch (const std::bad_alloc&) {
    code = print_error("out of memory");
  } catch (const std::exception& e) {
    code = print_error(e.what());
  }
  if (code == 0) keep_output_directories();
  else remove_output_directories();
  return code;
}
