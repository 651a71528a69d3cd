//
// yscene merge: the parts of a render made with --sample-range, added up into
// its image (or into one part).
//

#include <algorithm>
#include <cstdio>
#include <sstream>

#include "yscene_cli.h"

using namespace yocto;

// -----------------------------------------------------------------------------
// MERGE
// -----------------------------------------------------------------------------

// The first setting (a "key=value" line) in which a and b differ: a's line
// and b's line with that key, "(no KEY)" where one lacks it.
static std::pair<std::string, std::string> first_difference(
    const std::string& a, const std::string& b) {
  auto lines = [](const std::string& text) {
    auto result = std::vector<std::pair<std::string, std::string>>{};  // key, line
    auto stream = std::istringstream(text);
    for (auto line = std::string{}; std::getline(stream, line);)
      result.push_back({line.substr(0, line.find('=')), line});
    return result;
  };
  auto lines_a = lines(a), lines_b = lines(b);
  auto find    = [](const auto& lines, const std::string& key) {
    for (auto& [other, line] : lines)
      if (other == key) return line;
    return "(no " + key + ")";
  };
  for (auto& [key, line] : lines_a)
    if (auto other = find(lines_b, key); other != line) return {line, other};
  for (auto& [key, line] : lines_b)
    if (auto other = find(lines_a, key); other != line) return {other, line};
  return {"", ""};
}

// Adds up parts of one render: they must share the scene and settings and
// cover [0, N) once (for an image) or one range without gaps (for a part).
// The sums are exact, so the image has the bits of a render on one machine.
int run_merge(const merge_options& options) {
  auto& output = options.output;
  if (options.part && path_extension(output) != ".exr")
    return print_error(output + ": a render part is an OpenEXR image: use a name ending in .exr");
  if (!options.part && !is_image_filename(output))
    return print_error(output + ": unknown image extension (use exr, hdr, pfm, png or jpg)");
  struct part_range {
    std::string filename = "";
    int         first = 0, end = 0;
  };
  auto ranges = std::vector<part_range>{};
  auto merged = render_part{};
  auto error  = std::string{};
  auto range_text = [](int first, int end) {
    return std::to_string(first) + ":" + std::to_string(end);
  };
  for (auto& filename : options.parts) {
    auto part = render_part{};
    if (!load_render_part(filename, part, error, memory_limit)) return print_error(error);
    if (ranges.empty()) {
      // Fail before the work if the output cannot be written.
      auto pixel_bytes = options.part ? render_part_pixel_bytes + part.extra * render_part_extra_bytes
                                      : 12 + (part.extra > 0 ? 23 * 4 : 0);
      auto bytes       = (double)part.width * part.height * pixel_bytes + 65536;
      if (!check_output_file(output, bytes, error)) return print_error(error);
      merged.settings = part.settings;
      merged.samples  = part.samples;
      merged.width    = part.width;
      merged.height   = part.height;
      merged.sums.assign(part.sums.size(), fixed_sum3{});
      merged.extra = part.extra;
      merged.extra_sums.assign(part.extra_sums.size(), fixed_sum3{});
    }
    auto& reference = ranges.empty() ? filename : ranges.front().filename;
    if (part.samples != merged.samples)
      return print_error(filename + ": a part of a " + std::to_string(part.samples) +
                         "-sample render, but " + reference + " is of a " +
                         std::to_string(merged.samples) + "-sample one");
    if (part.settings != merged.settings) {
      auto [here, there] = first_difference(part.settings, merged.settings);
      auto hint = here.rfind("isa=", 0) == 0
                      ? "; machines with different CPUs agree when every part gets the same "
                        "--embree-config max_isa=NAME"
                  : here.rfind("renderer=", 0) == 0
                      ? "; render every part with one build of yscene"
                      : "";
      return print_error(filename + ": not a part of the render of " + reference + ": " + here +
                         " here, " + there + " there (parts of one render share the scene "
                         "and every setting" + hint + ")");
    }
    if (part.width != merged.width || part.height != merged.height ||
        part.sums.size() != merged.sums.size())
      return print_error(filename + ": " + std::to_string(part.width) + "x" +
                         std::to_string(part.height) + " pixels, but " + reference + " has " +
                         std::to_string(merged.width) + "x" + std::to_string(merged.height));
    // The settings say whether a render has AOVs; a part that lacks them
    // where its settings say it has them is damaged or not ours.
    if (part.extra != merged.extra || part.extra_sums.size() != merged.extra_sums.size())
      return print_error(filename + ": " + std::to_string(part.extra) +
                         " extra sums a pixel, but " + reference + " has " +
                         std::to_string(merged.extra));
    for (size_t i = 0; i < part.sums.size(); i++) add_fixed(merged.sums[i], part.sums[i]);
    for (size_t i = 0; i < part.extra_sums.size(); i++)
      add_fixed(merged.extra_sums[i], part.extra_sums[i]);
    merged.rays += part.rays;
    merged.nonfinite += part.nonfinite;
    ranges.push_back({filename, part.first, part.first + part.count});
  }
  // Each sample once: sorted by range, neighbours neither overlap nor leave
  // a gap; an image needs all of [0, N).
  std::stable_sort(ranges.begin(), ranges.end(),
      [](const part_range& a, const part_range& b) { return a.first < b.first; });
  for (size_t i = 1; i < ranges.size(); i++) {
    auto &before = ranges[i - 1], &after = ranges[i];
    if (after.first < before.end)
      return print_error(after.filename + ": samples " + range_text(after.first, after.end) +
                         " overlap those of " + before.filename + " (" +
                         range_text(before.first, before.end) + ")");
    if (after.first > before.end)
      return print_error("samples " + range_text(before.end, after.first) +
                         " are in no part: a gap between " + before.filename + " (" +
                         range_text(before.first, before.end) + ") and " + after.filename +
                         " (" + range_text(after.first, after.end) + ")");
  }
  auto first = ranges.front().first, end = ranges.back().end;
  if (!options.part && first > 0)
    return print_error("samples " + range_text(0, first) + " of " +
                       std::to_string(merged.samples) + " are in no part (the first, " +
                       ranges.front().filename + ", starts at " + std::to_string(first) + ")");
  if (!options.part && end < merged.samples)
    return print_error("samples " + range_text(end, merged.samples) + " of " +
                       std::to_string(merged.samples) + " are in no part (the last, " +
                       ranges.back().filename + ", ends at " + std::to_string(end) + ")");
  merged.first = first;
  merged.count = end - first;
  if (!make_output_directory(output, error)) return print_error(error);
  auto aovs = merged.extra == trace_aov_sums;
  if (merged.extra > 0 && !aovs)
    return print_error(ranges.front().filename + ": " + std::to_string(merged.extra) +
                       " extra sums a pixel, not the " + std::to_string(trace_aov_sums) +
                       " of the AOVs of this yscene");
  if (aovs && !options.part && path_extension(output) != ".exr")
    std::fprintf(stderr, "warning: %s keeps the beauty alone: the parts' AOVs are saved as "
                         "layers of an .exr output\n", output.c_str());
  auto image = options.part ? texture_data{}
                            : get_image(merged.width, merged.height, merged.sums,
                                  merged.samples);
  auto layers = aovs && !options.part && path_extension(output) == ".exr"
                    ? get_aov_layers(merged.width, merged.height, merged.extra_sums,
                          merged.samples)
                    : std::vector<image_layer>{};
  auto saved  = options.part ? save_render_part(output, merged, error)
                             : save_render_image(output, image, layers, error, options.exposure);
  if (!saved) return print_error(error);
  if (merged.nonfinite > 0)
    std::fprintf(stderr, "warning: %lld NaN or Inf samples were dropped\n",
        (long long)merged.nonfinite);
  if (!options.quiet)
    std::printf("merged %zu parts into %s: %dx%d, samples %s of %d (%s rays)\n",
        ranges.size(), output.c_str(), merged.width, merged.height,
        range_text(first, end).c_str(), merged.samples, format_count((double)merged.rays).c_str());
  return 0;
}

CLI::App* add_merge_command(CLI::App& app, merge_options& options, std::string& max_memory) {
  auto merge      = app.add_subcommand("merge",
      "add up the parts of a render made with --sample-range into its image (bit for bit the "
      "image of one render)");
  merge->add_option("parts", options.parts, "render parts (.exr), in any order")
      ->required();
  merge->add_option("--output,-o", options.output,
          "output image (exr, hdr, pfm, png, jpg), or a part (exr) with --part")
      ->required();
  merge->add_option("--exposure,-e", options.exposure, "exposure for png/jpg (stops)");
  merge->add_flag("--part", options.part,
      "write the merged parts as one part (their ranges must be contiguous), to merge later");
  merge->add_flag("--quiet,-q", options.quiet, "print nothing on success");
  add_max_memory_option(merge, max_memory);
  return merge;
}
