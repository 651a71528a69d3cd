//
// yscene's command line: what the commands share.
//

#include "yscene_cli.h"

#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>

using namespace yocto;

// -----------------------------------------------------------------------------
// SHARED HELPERS
// -----------------------------------------------------------------------------

int print_error(const std::string& message) {
  std::fprintf(stderr, "error: %s\n", message.c_str());
  return 1;
}

bool make_output_directory(const std::string& output, std::string& error) {
  if (make_output_directories(path_dirname(output), error)) return true;
  error = output + ": " + error;
  return false;
}

void handle_fatal_signal(int signal) {
  remove_pending_outputs();
  std::signal(signal, SIG_DFL);
  std::raise(signal);
}

void install_signal_handlers() {
  for (auto signal : {SIGINT, SIGTERM, SIGHUP, SIGQUIT}) std::signal(signal, handle_fatal_signal);
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::string format_count(double count) {
  char buffer[64];
  if (count >= 1e9) std::snprintf(buffer, sizeof(buffer), "%.2fG", count / 1e9);
  else if (count >= 1e6) std::snprintf(buffer, sizeof(buffer), "%.2fM", count / 1e6);
  else if (count >= 1e3) std::snprintf(buffer, sizeof(buffer), "%.2fk", count / 1e3);
  else std::snprintf(buffer, sizeof(buffer), "%.0f", count);
  return buffer;
}

void add_max_memory_option(CLI::App* command, std::string& max_memory) {
  command->add_option("--max-memory", max_memory,
      "memory a load may use: bytes or with a K, M or G suffix, e.g. 4G (default: 3/4 of "
      "physical memory, or of ulimit -v if lower)");
}

double memory_limit = default_memory_limit();

pbrt_params with_memory_limit(pbrt_params params) {
  params.max_memory = memory_limit;
  return params;
}

bool parse_memory_size(const std::string& text, double& bytes) {
  auto end   = (char*)nullptr;
  auto value = std::strtod(text.c_str(), &end);
  if (end == text.c_str()) return false;
  auto suffix = std::string(end);
  auto units  = std::string("KMGT");
  auto unit   = suffix.size() == 1 ? units.find((char)std::toupper((unsigned char)suffix[0]))
                                   : std::string::npos;
  if (!suffix.empty() && unit == std::string::npos) return false;
  bytes = suffix.empty() ? value : std::ldexp(value, 10 * (int)(unit + 1));
  return std::isfinite(bytes) && bytes >= 1;
}

bool save_render_image(const std::string& filename, const texture_data& image,
    const std::vector<image_layer>& layers, std::string& error, float exposure,
    bool replace) {
  if (!layers.empty()) return save_image_layers(filename, image, layers, error, replace);
  return save_image(filename, image, error, exposure, replace);
}
