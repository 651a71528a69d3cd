//
// Implementation of Yocto/PbrtIO.
//
// The pbrt reader tokenises each file from a memory buffer (plain files are
// read whole, .gz files through zlib), keeps pbrt's graphics state (current
// transform, material, area light) on a stack, and turns directives into scene
// elements as they come. Curves are appended to one shape per (material,
// transform), which is what keeps million-curve files fast.
//

#include "yocto_pbrtio.h"

#include <zlib.h>

#include <array>
#include <charconv>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <new>
#include <string_view>
#include <unordered_map>
#include <unordered_set>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "yocto_image.h"
#include "yocto_ply.h"

// -----------------------------------------------------------------------------
// FILE READING
// -----------------------------------------------------------------------------
namespace yocto {

static bool ends_with(std::string_view text, std::string_view suffix) {
  return text.size() >= suffix.size() &&
         text.substr(text.size() - suffix.size()) == suffix;
}

// Opens a file for reading and gives its size; only regular files are
// accepted: /dev/zero never ends, a directory has no text, and opening a fifo
// would wait for a writer (hence O_NONBLOCK, which regular files ignore).
static int open_regular_file(const std::string& filename, size_t& size, std::string& error) {
  auto fd = open(filename.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    error = filename + ": cannot open file (" + std::strerror(errno) + ")";
    return -1;
  }
  struct stat info = {};
  if (fstat(fd, &info) != 0 || !S_ISREG(info.st_mode)) {
    auto directory = S_ISDIR(info.st_mode);
    close(fd);
    error = filename + (directory ? ": is a directory, not a file"
                                  : ": not a regular file (a device, fifo or socket)");
    return -1;
  }
  size = (size_t)info.st_size;
  return fd;
}

// pbrt text deflates 3 to 10 times; only crafted data comes near deflate's
// limit of 1032 to 1. Past 16 MiB, a gzip'd file may inflate to at most 100
// times its size, so a small bomb fails after little work.
const auto max_inflation_ratio = 100.0;
const auto min_inflation_bound = 16.0 * (1 << 20);

// Reads an open regular file whole, closing it; .gz files are inflated. A
// gzip stream that ends early or fails its checksum is an error, never a
// silently short file. `held` bytes are already in use by the load: what is
// read is checked against the memory budget with them, before allocating.
static bool read_open_file(int fd, size_t size, const std::string& filename,
    std::string& data, std::string& error, double held, double max_memory) {
  data.clear();
  if (ends_with(filename, ".gz")) {
    auto file = gzdopen(fd, "rb");
    if (!file) {
      close(fd);
      error = filename + ": cannot open file";
      return false;
    }
    gzbuffer(file, 1 << 20);
    auto       max_size = std::max(min_inflation_bound, max_inflation_ratio * size);
    const auto chunk    = (size_t)1 << 22;
    auto       fail     = [&](const std::string& message) {
      gzclose_r(file);
      error = filename + ": " + message;
      data  = {};
      return false;
    };
    while (true) {
      auto old_size = data.size();
      if ((double)old_size > max_size)
        return fail("inflates past " +
                    std::to_string((long long)(min_inflation_bound / (1 << 20))) +
                    " MiB and to more than " + std::to_string((int)max_inflation_ratio) +
                    " times its compressed size: not pbrt text (a decompression bomb?)");
      // Grow by doubling, checking first: old and new buffers coexist.
      if (old_size + chunk > data.capacity()) {
        auto capacity = std::max(2 * data.capacity(), old_size + chunk);
        auto message  = std::string{};
        if (!check_load_memory(filename, "inflating the text",
                held + (double)data.capacity() + (double)capacity, max_memory, message)) {
          gzclose_r(file);
          error = message;
          data  = {};
          return false;
        }
        data.reserve(capacity);
      }
      data.resize(old_size + chunk);
      auto count = gzread(file, data.data() + old_size, (unsigned)chunk);
      if (count < 0) {
        auto errnum = 0;
        return fail("corrupt or truncated gzip data after " + std::to_string(old_size) +
                    " uncompressed bytes (" + gzerror(file, &errnum) + ")");
      }
      data.resize(old_size + (size_t)count);
      if (count == 0) break;
    }
    // gzclose_r reports Z_BUF_ERROR when the last read ended inside a stream.
    if (gzclose_r(file) != Z_OK) {
      error = filename + ": truncated gzip data after " + std::to_string(data.size()) +
              " uncompressed bytes";
      data = {};
      return false;
    }
    return true;
  }
  if (!check_load_memory(filename, "the text", held + (double)size, max_memory, error)) {
    close(fd);
    return false;
  }
  data.resize(size);
  auto read = (size_t)0;
  while (read < size) {
    auto count = ::read(fd, data.data() + read, size - read);
    if (count < 0 && errno == EINTR) continue;
    if (count <= 0) break;
    read += (size_t)count;
  }
  close(fd);
  if (read != size) {
    error = filename + ": cannot read file";
    data  = {};
    return false;
  }
  return true;
}

// A read-only memory mapping of a plain file, unmapped when it goes out of
// scope: large geometry files are parsed in place, without a private copy.
struct pbrt_file_mapping {
  void*  data = nullptr;
  size_t size = 0;
  pbrt_file_mapping() = default;
  pbrt_file_mapping(const pbrt_file_mapping&) = delete;
  pbrt_file_mapping& operator=(const pbrt_file_mapping&) = delete;
  ~pbrt_file_mapping() {
    if (data) munmap(data, size);
  }
};

// Maps an open plain, non-empty file; false if it is gzip'd or cannot be
// mapped (the caller then reads it). The file stays open.
static bool map_file(
    int fd, size_t size, const std::string& filename, pbrt_file_mapping& mapping) {
  if (ends_with(filename, ".gz") || size == 0) return false;
  auto data = mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
  if (data == MAP_FAILED) return false;
  madvise(data, size, MADV_SEQUENTIAL);
  mapping.data = data;
  mapping.size = size;
  return true;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// TOKENIZER
// -----------------------------------------------------------------------------
namespace yocto {

enum struct pbrt_token_kind { eof, word, string, number, open, close };

// A token points into the file buffer; strings exclude their quotes.
struct pbrt_token {
  pbrt_token_kind  kind    = pbrt_token_kind::eof;
  std::string_view text    = {};
  int              line    = 0;
  bool             escaped = false;  // string with backslash escapes
};

struct pbrt_lexer {
  std::string filename = "";
  std::string data     = "";
  const char* ptr      = nullptr;
  const char* end      = nullptr;
  int         line     = 1;
  pbrt_token  peeked   = {};
  bool        has_peek = false;
};

static std::string token_description(const pbrt_token& token) {
  switch (token.kind) {
    case pbrt_token_kind::eof: return "end of file";
    case pbrt_token_kind::open: return "[";
    case pbrt_token_kind::close: return "]";
    case pbrt_token_kind::string: return "\"" + std::string{token.text} + "\"";
    default: return std::string{token.text};
  }
}

static bool is_space(char c) {
  return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v';
}

// Character classes for the lexer's inner loops: whitespace, and characters
// that end a bare token (whitespace, brackets, quotes, comments).
enum : unsigned char { pbrt_space = 1, pbrt_delimiter = 2 };
static const auto pbrt_char_class = [] {
  auto table = std::array<unsigned char, 256>{};
  for (auto c : {' ', '\t', '\n', '\r', '\f', '\v'})
    table[(unsigned char)c] = pbrt_space | pbrt_delimiter;
  for (auto c : {'[', ']', '"', '#'}) table[(unsigned char)c] = pbrt_delimiter;
  return table;
}();

// Skips whitespace and # comments, counting lines.
static void skip_whitespace(pbrt_lexer& lexer) {
  auto& ptr = lexer.ptr;
  auto  end = lexer.end;
  while (ptr < end) {
    auto c = *ptr;
    if (pbrt_char_class[(unsigned char)c] & pbrt_space) {
      if (c == '\n') lexer.line++;
      ptr++;
    } else if (c == '#') {
      auto newline = (const char*)std::memchr(ptr, '\n', (size_t)(end - ptr));
      ptr          = newline ? newline : end;
    } else {
      break;
    }
  }
}

// Offset of the first byte that does not start a valid UTF-8 sequence, or
// npos. The second byte's range excludes overlong forms, surrogates and code
// points past U+10FFFF (RFC 3629), as the json writer does.
static size_t find_invalid_utf8(std::string_view text) {
  auto i = (size_t)0;
  while (i < text.size()) {
    auto c = (unsigned char)text[i];
    if (c < 0x80) {
      i++;
      continue;
    }
    auto length = 0;
    auto low = (unsigned char)0x80, high = (unsigned char)0xbf;
    if (c >= 0xc2 && c <= 0xdf) {
      length = 2;
    } else if (c >= 0xe0 && c <= 0xef) {
      length = 3;
      if (c == 0xe0) low = 0xa0;
      if (c == 0xed) high = 0x9f;
    } else if (c >= 0xf0 && c <= 0xf4) {
      length = 4;
      if (c == 0xf0) low = 0x90;
      if (c == 0xf4) high = 0x8f;
    } else {
      return i;
    }
    if (i + length > text.size()) return i;
    for (auto k = 1; k < length; k++) {
      auto b = (unsigned char)text[i + k];
      if (k == 1 ? (b < low || b > high) : (b < 0x80 || b > 0xbf)) return i;
    }
    i += length;
  }
  return std::string_view::npos;
}

// Text for a message: bytes outside printable ASCII as \xNN, at most 40.
static std::string printable(std::string_view text) {
  auto result = std::string{};
  for (auto c : text.substr(0, 40)) {
    if (c >= 0x20 && c < 0x7f) {
      result += c;
    } else {
      char buffer[8];
      std::snprintf(buffer, sizeof(buffer), "\\x%02X", (unsigned)(unsigned char)c);
      result += buffer;
    }
  }
  return text.size() > 40 ? result + "..." : result;
}

// Reads the next token; on a lexical error sets `error` (file and line).
static bool lex_token(pbrt_lexer& lexer, pbrt_token& token, std::string& error) {
  skip_whitespace(lexer);
  auto& ptr = lexer.ptr;
  auto  end = lexer.end;
  token     = {};
  token.line = lexer.line;
  if (ptr >= end) return true;
  auto c = *ptr;
  if (c == '[' || c == ']') {
    token.kind = c == '[' ? pbrt_token_kind::open : pbrt_token_kind::close;
    token.text = {ptr, 1};
    ptr++;
    return true;
  }
  if (c == '"') {
    auto start = ++ptr;
    auto bits  = (unsigned char)0;  // high bit set: not all ASCII
    while (ptr < end && *ptr != '"' && *ptr != '\n') {
      if (*ptr == '\\' && ptr + 1 < end && ptr[1] != '\n') {
        token.escaped = true;
        ptr++;
      }
      bits |= (unsigned char)*ptr;
      ptr++;
    }
    if (ptr >= end || *ptr != '"') {
      error = lexer.filename + ":" + std::to_string(token.line) +
              ": unterminated string \"" +
              std::string{start, (size_t)std::min<ptrdiff_t>(ptr - start, 40)} + "\"";
      return false;
    }
    token.kind = pbrt_token_kind::string;
    token.text = {start, (size_t)(ptr - start)};
    ptr++;
    // Strings become names and json keys, which must be UTF-8.
    auto invalid = (bits & 0x80) ? find_invalid_utf8(token.text) : std::string_view::npos;
    if (invalid != std::string_view::npos) {
      char byte[8];
      std::snprintf(byte, sizeof(byte), "0x%02X", (unsigned)(unsigned char)token.text[invalid]);
      error = lexer.filename + ":" + std::to_string(token.line) + ": string \"" +
              printable(token.text) + "\" is not valid UTF-8 (byte " + byte + " at offset " +
              std::to_string(invalid) + " in the string)";
      return false;
    }
    return true;
  }
  auto start = ptr;
  while (ptr < end && !(pbrt_char_class[(unsigned char)*ptr] & pbrt_delimiter)) ptr++;
  token.text = {start, (size_t)(ptr - start)};
  token.kind = (c >= '0' && c <= '9') || c == '-' || c == '+' || c == '.'
                   ? pbrt_token_kind::number
                   : pbrt_token_kind::word;
  return true;
}

static bool next_token(pbrt_lexer& lexer, pbrt_token& token, std::string& error) {
  if (lexer.has_peek) {
    lexer.has_peek = false;
    token          = lexer.peeked;
    return true;
  }
  return lex_token(lexer, token, error);
}

static bool peek_token(pbrt_lexer& lexer, pbrt_token& token, std::string& error) {
  if (!lexer.has_peek) {
    if (!lex_token(lexer, lexer.peeked, error)) return false;
    lexer.has_peek = true;
  }
  token = lexer.peeked;
  return true;
}

// Decimal numbers whose digits fit in a float's 24-bit mantissa and whose
// exponent is at most 10 in magnitude are parsed exactly with one float
// multiply or divide, since both operands are exact (Clinger, How to Read
// Floating Point Numbers Accurately, PLDI 1990). Returns the end of the
// number, or nullptr to fall back to std::from_chars.
static const char* parse_float_fast(const char* ptr, const char* end, float& value) {
  static const float powers[] = {1e0f, 1e1f, 1e2f, 1e3f, 1e4f, 1e5f, 1e6f, 1e7f, 1e8f, 1e9f, 1e10f};
  auto is_digit = [&](const char* p) { return p < end && (unsigned)(*p - '0') < 10; };
  auto negative = ptr < end && *ptr == '-';
  if (ptr < end && (*ptr == '-' || *ptr == '+')) ptr++;
  auto mantissa = (uint32_t)0;
  auto digits = 0, exponent = 0;
  for (; is_digit(ptr); ptr++, digits++) {
    mantissa = mantissa * 10 + (uint32_t)(*ptr - '0');
    if (mantissa > (1u << 24)) return nullptr;
  }
  if (ptr < end && *ptr == '.') {
    for (ptr++; is_digit(ptr); ptr++, digits++, exponent--) {
      mantissa = mantissa * 10 + (uint32_t)(*ptr - '0');
      if (mantissa > (1u << 24)) return nullptr;
    }
  }
  if (digits == 0) return nullptr;
  if (ptr < end && (*ptr == 'e' || *ptr == 'E')) {
    ptr++;
    auto sign = 1;
    if (ptr < end && (*ptr == '-' || *ptr == '+')) sign = *ptr++ == '-' ? -1 : 1;
    if (!is_digit(ptr)) return nullptr;
    auto e = 0;
    for (; is_digit(ptr); ptr++) {
      e = e * 10 + (*ptr - '0');
      if (e > 100) return nullptr;
    }
    exponent += sign * e;
  }
  if (exponent < -10 || exponent > 10) return nullptr;
  auto result = exponent < 0 ? (float)mantissa / powers[-exponent]
                             : (float)mantissa * powers[exponent];
  value = negative ? -result : result;
  return ptr;
}

// Parses a whole token as a float; `.3`, `-0`, `+1`, `1e-3` are numbers.
static bool parse_float(std::string_view text, float& value) {
  auto fast_end = parse_float_fast(text.data(), text.data() + text.size(), value);
  if (fast_end == text.data() + text.size()) return true;
  if (!text.empty() && text[0] == '+') text.remove_prefix(1);
  if (text.empty()) return false;
  auto result = std::from_chars(text.data(), text.data() + text.size(), value);
  if (result.ec == std::errc::result_out_of_range) {
    // Underflow is fine (a tiny number), overflow is not.
    auto copy   = std::string{text};
    auto parsed = std::strtod(copy.c_str(), nullptr);
    if (!std::isfinite(parsed) || std::abs(parsed) > flt_max) return false;
    value = (float)parsed;
    return true;
  }
  return result.ec == std::errc{} && result.ptr == text.data() + text.size();
}

static std::string unescape_string(const pbrt_token& token) {
  if (!token.escaped) return std::string{token.text};
  auto result = std::string{};
  for (auto i = (size_t)0; i < token.text.size(); i++) {
    auto c = token.text[i];
    if (c == '\\' && i + 1 < token.text.size()) {
      c = token.text[++i];
      switch (c) {
        case 'n': c = '\n'; break;
        case 't': c = '\t'; break;
        case 'r': c = '\r'; break;
        case 'b': c = '\b'; break;
        case 'f': c = '\f'; break;
        default: break;
      }
    }
    result.push_back(c);
  }
  return result;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// PARAMETERS
// -----------------------------------------------------------------------------
namespace yocto {

// One "type name" value list. Booleans are stored as numbers 0/1. Type and
// name point into the file buffer, valid while the directive is parsed.
struct pbrt_param {
  std::string_view         type    = {};
  std::string_view         name    = {};
  std::vector<float>       numbers = {};
  std::vector<std::string> strings = {};
  int                      line    = 0;
  bool                     used    = false;
  bool                     integer = false;  // values must be integral
};

// Parameters of the current directive; entries are reused to avoid
// allocations on the per-curve path.
struct pbrt_param_list {
  std::vector<pbrt_param> items = {};
  int                     count = 0;
};

enum struct pbrt_value_kind { numbers, strings, bools, spectrum };

static bool param_value_kind(std::string_view type, pbrt_value_kind& kind) {
  if (type == "float" || type == "point" || type == "point3" || type == "integer" ||
      type == "rgb" || type == "normal" || type == "normal3" || type == "point2" ||
      type == "vector" || type == "vector2" || type == "vector3" || type == "color" ||
      type == "blackbody") {
    kind = pbrt_value_kind::numbers;
  } else if (type == "string" || type == "texture") {
    kind = pbrt_value_kind::strings;
  } else if (type == "bool") {
    kind = pbrt_value_kind::bools;
  } else if (type == "spectrum") {
    kind = pbrt_value_kind::spectrum;
  } else {
    return false;
  }
  return true;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// PARSER STATE
// -----------------------------------------------------------------------------
namespace yocto {

// pbrt's per-attribute-block state.
struct pbrt_graphics_state {
  frame3f ctm      = identity3x4f;
  int     material = 0;  // index into pbrt_state::materials
  vec3f   emission = {0, 0, 0};
  bool    reverse_orientation = false;  // ReverseOrientation: area lights emit backwards
};

struct pbrt_stack_entry {
  pbrt_graphics_state graphics  = {};
  bool                attribute = true;  // AttributeBegin or TransformBegin
  int                 line      = 0;
};

// Curves of one material and transform, appended to one shape.
struct pbrt_curve_group {
  int shape       = -1;
  int last_vertex = -1;  // end vertex of the last curve, for chaining
};

struct pbrt_camera_state {
  frame3f camera_to_world = identity3x4f;
  float   fov             = 90;
  float   focus           = 0;
  float   aperture        = 0;
};

// Constant value of a named texture, if it has one.
struct pbrt_texture {
  bool  constant = false;
  vec3f value    = {1, 1, 1};
};

struct pbrt_state {
  scene_data*               scene    = nullptr;
  pbrt_params               params   = {};
  std::vector<std::string>* warnings = nullptr;
  std::string               error    = "";

  // Directive being parsed, for messages.
  pbrt_lexer*      lexer     = nullptr;
  std::string_view directive = {};
  std::string_view type      = {};
  int              line      = 0;
  pbrt_param_list  list      = {};

  // Graphics state.
  pbrt_graphics_state                      graphics = {};
  std::vector<pbrt_stack_entry>            stack    = {};
  std::unordered_map<std::string, frame3f> coordinate_systems = {};
  std::vector<std::string>                 open_files         = {};

  // Materials as declared (index 0 is pbrt's default diffuse); scene
  // materials are made from them on first use with an emission.
  std::vector<material_data>                           materials = {};
  std::vector<std::string>                             material_names = {};
  std::unordered_map<std::string, int>                 named_materials = {};
  std::map<std::tuple<int, float, float, float>, int> scene_materials = {};
  std::unordered_map<std::string, pbrt_texture>        textures = {};
  int   last_material       = -1;  // cache of current_scene_material
  vec3f last_emission       = {0, 0, 0};
  int   last_scene_material = -1;

  // Curve groups and a cache of the last one used.
  std::map<std::pair<int, std::array<float, 12>>, int> group_keys = {};
  std::vector<pbrt_curve_group>                        groups     = {};
  int                                                  last_group = -1;
  int     last_group_material = -1;
  frame3f last_group_ctm      = {};

  std::vector<std::array<vec3f, 4>> segments = {};  // reused by each curve

  pbrt_camera_state camera     = {};
  bool              has_camera = false;
  vec2i             film       = {0, 0};
  bool              has_film   = false;

  // A camera-only load stops at the first WorldBegin.
  bool camera_only = false;
  bool world_begun = false;

  std::unordered_set<std::string> warned = {};

  // Memory and work of the load, for the budget (see memory_in_use).
  double scene_bytes  = 0;  // shapes, instances and textures in the scene
  double text_bytes   = 0;  // text of open files read into memory
  double param_bytes  = 0;  // capacity of the parameter value lists
  double parsed_bytes = 0;  // text parsed so far, with every Include
};

static std::string location(const pbrt_state& state, int line = -1) {
  return state.lexer->filename + ":" + std::to_string(line < 0 ? state.line : line) + ": ";
}

static std::string directive_name(const pbrt_state& state) {
  auto name = std::string{state.directive};
  if (!state.type.empty()) name += " \"" + std::string{state.type} + "\"";
  return name;
}

// Records the first error of a directive.
static void set_error(pbrt_state& state, const std::string& message, int line = -1) {
  if (!state.error.empty()) return;
  state.error = location(state, line) + directive_name(state) + ": " + message;
}

// Memory the load holds: the scene so far, the text of the open files, the
// parameter lists, and the parser's own state (blocks, materials, names;
// bytes per table entry estimated). Checked against params.max_memory after
// each directive and before each large allocation, so repeated Includes of
// small files cannot build an unbounded scene.
static double memory_in_use(const pbrt_state& state) {
  const auto entry_bytes = 64.0;  // a hash or tree node with a short name
  auto       entries     = state.textures.size() + state.named_materials.size() +
                 state.coordinate_systems.size() + state.scene_materials.size() +
                 state.group_keys.size() + state.warned.size();
  return state.scene_bytes + state.text_bytes + state.param_bytes +
         (double)state.stack.size() * sizeof(pbrt_stack_entry) +
         (double)state.materials.size() * (sizeof(material_data) + sizeof(std::string)) +
         (double)state.groups.size() * sizeof(pbrt_curve_group) + entries * entry_bytes;
}

// Fails the directive with "FILE:LINE: DIRECTIVE: WHAT needs N MiB, over the
// memory limit..." if `bytes` exceed the budget.
static bool check_memory(pbrt_state& state, const std::string& what, double bytes, int line = -1) {
  if (bytes <= state.params.max_memory) return true;
  auto error = std::string{};
  check_load_memory(state.lexer->filename + ":" + std::to_string(line < 0 ? state.line : line),
      directive_name(state) + ": " + what, bytes, state.params.max_memory, error);
  if (state.error.empty()) state.error = error;
  return false;
}

// Bytes the scene keeps for a shape: its arrays, its instance and the names.
static double shape_bytes(const shape_data& shape) {
  return shape_memory(shape) + sizeof(shape_data) + sizeof(instance_data) +
         2 * sizeof(std::string);
}

static double texture_bytes(const texture_data& texture) {
  return (double)texture.pixels.size() * sizeof(vec3f) + sizeof(texture_data) +
         sizeof(std::string);
}

// Checks that a file the scene names is a regular file before a reader opens
// it: the PLY and image readers would read a device forever or wait on a
// fifo for a writer.
static bool check_regular_file(pbrt_state& state, const std::string& path, const std::string& name) {
  struct stat info = {};
  if (stat(path.c_str(), &info) != 0) {
    set_error(state, "cannot find \"" + name + "\" (" + path + ")");
    return false;
  }
  if (!S_ISREG(info.st_mode)) {
    set_error(state, "\"" + name + "\" (" + path + ") is " +
                         (S_ISDIR(info.st_mode) ? "a directory, not a file"
                                                : "not a regular file (a device, fifo or socket)"));
    return false;
  }
  return true;
}

static void add_warning(pbrt_state& state, const std::string& message) {
  if (state.warnings) {
    state.warnings->push_back(message);
  } else {
    std::fprintf(stderr, "warning: %s\n", message.c_str());
  }
}

// Warns once per key; the message gets the file and line.
static void warn_once(pbrt_state& state, const std::string& key, const std::string& message) {
  if (!state.warned.insert(key).second) return;
  add_warning(state, location(state) + message);
}

static std::string param_decl(const pbrt_param& param) {
  return "\"" + std::string{param.type} + " " + std::string{param.name} + "\"";
}

// Finds a parameter by name and marks it used.
static pbrt_param* find_param(pbrt_state& state, std::string_view name) {
  for (auto i = 0; i < state.list.count; i++) {
    auto& param = state.list.items[i];
    if (param.name == name) {
      param.used = true;
      return &param;
    }
  }
  return nullptr;
}

static void type_error(pbrt_state& state, const pbrt_param& param, const char* expected) {
  set_error(state, "parameter " + param_decl(param) + " should be " + expected, param.line);
}

static bool check_count(pbrt_state& state, const pbrt_param& param, size_t count) {
  auto size = param.numbers.size() + param.strings.size();
  if (size == count) return true;
  set_error(state,
      "parameter " + param_decl(param) + " needs " + std::to_string(count) +
          " value(s), got " + std::to_string(size),
      param.line);
  return false;
}

// Value of a named texture used where a constant is expected.
static bool texture_constant(pbrt_state& state, const pbrt_param& param, vec3f& value) {
  if (!check_count(state, param, 1)) return false;
  auto it = state.textures.find(param.strings[0]);
  if (it == state.textures.end()) {
    set_error(state, "unknown texture \"" + param.strings[0] + "\"", param.line);
    return false;
  }
  if (it->second.constant) {
    value = it->second.value;
    return true;
  }
  warn_once(state, "texture " + std::string{param.name} + param.strings[0],
      directive_name(state) + ": texture \"" + param.strings[0] + "\" for " +
          param_decl(param) + " is not supported; using a constant");
  return false;
}

static float get_float(pbrt_state& state, std::string_view name, float value) {
  auto param = find_param(state, name);
  if (!param) return value;
  if (param->type == "float") {
    if (check_count(state, *param, 1)) return param->numbers[0];
  } else if (param->type == "texture") {
    auto color = vec3f{value};
    if (texture_constant(state, *param, color)) return mean(color);
  } else {
    type_error(state, *param, "a float");
  }
  return value;
}

// A parameter with one value of the given type; nullptr if it is absent or
// wrong (the error is recorded).
static const pbrt_param* find_single(pbrt_state& state, std::string_view name,
    std::string_view type, const char* expected) {
  auto param = find_param(state, name);
  if (!param) return nullptr;
  if (param->type != type) {
    type_error(state, *param, expected);
    return nullptr;
  }
  return check_count(state, *param, 1) ? param : nullptr;
}

static int get_int(pbrt_state& state, std::string_view name, int value) {
  auto param = find_single(state, name, "integer", "an integer");
  return param ? (int)param->numbers[0] : value;
}

static bool get_bool(pbrt_state& state, std::string_view name, bool value) {
  auto param = find_single(state, name, "bool", "a bool");
  return param ? param->numbers[0] != 0 : value;
}

static std::string get_string(pbrt_state& state, std::string_view name, const std::string& value) {
  auto param = find_single(state, name, "string", "a string");
  return param ? param->strings[0] : value;
}

// Approximate linear RGB of a blackbody at `temperature` kelvin, normalised
// to a maximum of 1: Planck's law sampled at one wavelength per channel.
static vec3f blackbody_to_rgb(float temperature) {
  auto planck = [&](double lambda_nm) {
    const auto h = 6.62606957e-34, c = 299792458.0, kb = 1.3806488e-23;
    auto       l = lambda_nm * 1e-9;
    return (2 * h * c * c) / (std::pow(l, 5) * (std::exp((h * c) / (l * kb * temperature)) - 1));
  };
  if (!(temperature > 0)) return {0, 0, 0};
  auto rgb = vec3f{(float)planck(610), (float)planck(550), (float)planck(465)};
  auto m   = max_component(rgb);
  return m > 0 && std::isfinite(m) ? rgb / m : vec3f{1, 1, 1};
}

// Colour parameters: rgb/color, a float (grey), spectrum (approximated by its
// mean), blackbody (approximated) or a constant texture.
static vec3f get_rgb(pbrt_state& state, std::string_view name, const vec3f& value) {
  auto param = find_param(state, name);
  if (!param) return value;
  auto& type = param->type;
  if (type == "rgb" || type == "color") {
    if (check_count(state, *param, 3))
      return {param->numbers[0], param->numbers[1], param->numbers[2]};
  } else if (type == "float") {
    if (check_count(state, *param, 1)) return vec3f{param->numbers[0]};
  } else if (type == "spectrum") {
    if (!param->strings.empty()) {
      warn_once(state, "spectrum " + param->strings[0],
          directive_name(state) + ": named spectrum \"" + param->strings[0] +
              "\" is not supported; using the default value");
    } else if (param->numbers.size() < 2 || param->numbers.size() % 2 != 0) {
      set_error(state, "parameter " + param_decl(*param) + " needs wavelength-value pairs",
          param->line);
    } else {
      warn_once(state, "spectrum", directive_name(state) +
                                       ": sampled spectra are approximated by their mean value");
      auto sum = 0.0f;
      for (auto i = (size_t)1; i < param->numbers.size(); i += 2) sum += param->numbers[i];
      return vec3f{sum / (param->numbers.size() / 2)};
    }
  } else if (type == "blackbody") {
    if (param->numbers.empty() || param->numbers.size() > 2) {
      set_error(state, "parameter " + param_decl(*param) + " needs a temperature", param->line);
    } else {
      warn_once(state, "blackbody", directive_name(state) +
                                        ": blackbody emission is approximated in RGB");
      auto scale = param->numbers.size() == 2 ? param->numbers[1] : 1.0f;
      return blackbody_to_rgb(param->numbers[0]) * scale;
    }
  } else if (type == "texture") {
    auto color = value;
    if (texture_constant(state, *param, color)) return color;
  } else {
    type_error(state, *param, "a colour (rgb, spectrum, blackbody)");
  }
  return value;
}

// Arrays of 3-vectors (point, normal, vector) and of floats.
static const std::vector<float>* get_array(pbrt_state& state, std::string_view name,
    std::initializer_list<std::string_view> types, int stride) {
  auto param = find_param(state, name);
  if (!param) return nullptr;
  for (auto type : types) {
    if (param->type != type) continue;
    if (param->numbers.size() % stride != 0) {
      set_error(state,
          "parameter " + param_decl(*param) + " needs a multiple of " +
              std::to_string(stride) + " values, got " +
              std::to_string(param->numbers.size()),
          param->line);
      return nullptr;
    }
    return &param->numbers;
  }
  type_error(state, *param, std::string{*types.begin()}.c_str());
  return nullptr;
}

// Reports parameters nobody read, once per directive and parameter.
static void warn_unused_params(pbrt_state& state) {
  for (auto i = 0; i < state.list.count; i++) {
    auto& param = state.list.items[i];
    if (param.used) continue;
    auto name = directive_name(state);
    warn_once(state, name + param_decl(param),
        name + ": ignoring parameter " + param_decl(param));
  }
}

// Integers are stored as floats, exact up to 2^24.
static bool is_integer(float value) {
  return value == std::floor(value) && std::abs(value) <= (float)(1 << 24);
}

// Doubles the capacity of a parameter's value list, checking the budget
// first: a huge array fails at its line instead of exhausting memory. Lists
// are reused by later directives, so their capacity stays counted.
template <typename T>
static bool grow_values(pbrt_state& state, const pbrt_param& param, std::vector<T>& values) {
  auto capacity = std::max(2 * values.capacity(), (size_t)64);
  auto growth   = (double)(capacity - values.capacity()) * sizeof(T);
  // While the list grows, its old and new buffers coexist.
  if (!check_memory(state, "the scene with parameter " + param_decl(param),
          memory_in_use(state) + (double)capacity * sizeof(T), param.line))
    return false;
  values.reserve(capacity);
  state.param_bytes += growth;
  return true;
}

// Parses one value of a parameter into `param`.
static bool parse_param_value(pbrt_state& state, pbrt_param& param,
    pbrt_value_kind kind, const pbrt_token& token) {
  auto bad = [&](const char* expected) {
    set_error(state,
        "parameter " + param_decl(param) + ": expected " + expected + ", got " +
            token_description(token),
        token.line);
    return false;
  };
  if (token.kind == pbrt_token_kind::number) {
    if (kind == pbrt_value_kind::strings) return bad("a string");
    if (kind == pbrt_value_kind::bools) return bad("true or false");
    if (kind == pbrt_value_kind::spectrum && !param.strings.empty())
      return bad("a string");
    auto value = 0.0f;
    if (!parse_float(token.text, value)) return bad("a number");
    if (param.integer && !is_integer(value)) return bad("an integer (at most 2^24)");
    if (param.numbers.size() == param.numbers.capacity() &&
        !grow_values(state, param, param.numbers))
      return false;
    param.numbers.push_back(value);
    return true;
  }
  if (token.kind == pbrt_token_kind::string || token.kind == pbrt_token_kind::word) {
    if (kind == pbrt_value_kind::bools) {
      if (token.text != "true" && token.text != "false") return bad("true or false");
      if (param.numbers.size() == param.numbers.capacity() &&
          !grow_values(state, param, param.numbers))
        return false;
      param.numbers.push_back(token.text == "true" ? 1 : 0);
      return true;
    }
    if (token.kind == pbrt_token_kind::word) return bad("a value");
    if (kind == pbrt_value_kind::numbers) return bad("a number");
    if (kind == pbrt_value_kind::spectrum && !param.numbers.empty())
      return bad("a number");
    if (param.strings.size() == param.strings.capacity() &&
        !grow_values(state, param, param.strings))
      return false;
    param.strings.push_back(unescape_string(token));
    return true;
  }
  return bad("a value");
}

// Parses the "type name" value lists that follow a directive.
static bool parse_params(pbrt_state& state) {
  auto& lexer = *state.lexer;
  auto& list  = state.list;
  list.count  = 0;
  auto token  = pbrt_token{};
  while (true) {
    if (!peek_token(lexer, token, state.error)) return false;
    if (token.kind != pbrt_token_kind::string) return true;
    next_token(lexer, token, state.error);
    // Declaration: type and name separated by spaces or tabs.
    auto decl = token.text;
    while (!decl.empty() && is_space(decl.front())) decl.remove_prefix(1);
    while (!decl.empty() && is_space(decl.back())) decl.remove_suffix(1);
    auto split = (size_t)0;
    while (split < decl.size() && !is_space(decl[split])) split++;
    auto type = decl.substr(0, split);
    auto name = decl.substr(split);
    while (!name.empty() && is_space(name.front())) name.remove_prefix(1);
    auto kind = pbrt_value_kind::numbers;
    if (name.empty() || std::any_of(name.begin(), name.end(), is_space)) {
      set_error(state, "bad parameter declaration \"" + std::string{token.text} +
                           "\" (expected \"type name\")", token.line);
      return false;
    }
    if (!param_value_kind(type, kind)) {
      set_error(state, "unknown parameter type \"" + std::string{type} + "\" in \"" +
                           std::string{token.text} + "\"", token.line);
      return false;
    }
    if (list.count == (int)list.items.size()) list.items.emplace_back();
    auto& param = list.items[list.count++];
    param.type = type;
    param.name = name;
    param.numbers.clear();
    param.strings.clear();
    param.line    = token.line;
    param.used    = false;
    param.integer = type == "integer";
    // Values: a bracketed list or a single value.
    if (!next_token(lexer, token, state.error)) return false;
    if (token.kind == pbrt_token_kind::open) {
      auto open_line = token.line;
      while (true) {
        // Fast path for the common case, a plain number: parse it in place.
        if (kind == pbrt_value_kind::numbers) {
          skip_whitespace(lexer);
          auto value      = 0.0f;
          auto number_end = parse_float_fast(lexer.ptr, lexer.end, value);
          if (number_end &&
              (number_end == lexer.end ||
                  (pbrt_char_class[(unsigned char)*number_end] & pbrt_delimiter)) &&
              (!param.integer || is_integer(value))) {
            if (param.numbers.size() == param.numbers.capacity() &&
                !grow_values(state, param, param.numbers))
              return false;
            param.numbers.push_back(value);
            lexer.ptr = number_end;
            continue;
          }
        }
        if (!next_token(lexer, token, state.error)) return false;
        if (token.kind == pbrt_token_kind::close) break;
        if (token.kind == pbrt_token_kind::eof || token.kind == pbrt_token_kind::open) {
          set_error(state, "parameter " + param_decl(param) + ": unterminated [ opened at line " +
                               std::to_string(open_line), token.line);
          return false;
        }
        if (!parse_param_value(state, param, kind, token)) return false;
      }
    } else {
      if (!parse_param_value(state, param, kind, token)) return false;
    }
  }
}

// Reads `count` numbers, bracketed or not.
static bool parse_numbers(pbrt_state& state, float* values, int count) {
  auto& lexer = *state.lexer;
  auto  token = pbrt_token{};
  if (!peek_token(lexer, token, state.error)) return false;
  auto bracket = token.kind == pbrt_token_kind::open;
  if (bracket) next_token(lexer, token, state.error);
  for (auto i = 0; i < count; i++) {
    if (!next_token(lexer, token, state.error)) return false;
    if (token.kind != pbrt_token_kind::number || !parse_float(token.text, values[i])) {
      set_error(state, "expected " + std::to_string(count) + " numbers, got " +
                           token_description(token) + " as value " + std::to_string(i + 1),
          token.line);
      return false;
    }
  }
  if (bracket) {
    if (!next_token(lexer, token, state.error)) return false;
    if (token.kind != pbrt_token_kind::close) {
      set_error(state, "expected ] after " + std::to_string(count) + " numbers, got " +
                           token_description(token), token.line);
      return false;
    }
  }
  return true;
}

static bool parse_string(pbrt_state& state, std::string_view& value, const char* what) {
  auto token = pbrt_token{};
  if (!next_token(*state.lexer, token, state.error)) return false;
  if (token.kind != pbrt_token_kind::string) {
    set_error(state, std::string{"expected "} + what + " (a quoted string), got " +
                         token_description(token), token.line);
    return false;
  }
  value = token.text;
  return true;
}

// Skips the arguments of a directive we do not use: everything up to the
// next directive name.
static bool skip_arguments(pbrt_state& state) {
  auto token = pbrt_token{};
  while (true) {
    if (!peek_token(*state.lexer, token, state.error)) return false;
    if (token.kind == pbrt_token_kind::eof) return true;
    if (token.kind == pbrt_token_kind::word && token.text != "true" && token.text != "false")
      return true;
    next_token(*state.lexer, token, state.error);
  }
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// TRANSFORMS AND CAMERA
// -----------------------------------------------------------------------------
namespace yocto {

static bool is_finite(const frame3f& frame) {
  return isfinite(frame.x) && isfinite(frame.y) && isfinite(frame.z) && isfinite(frame.o);
}

// pbrt's 16 numbers are the matrix in column-major order (the translation is
// values 12..14); only affine matrices are supported.
static bool matrix_to_frame(pbrt_state& state, const float* values, frame3f& frame) {
  auto w = values[15];
  if (values[3] != 0 || values[7] != 0 || values[11] != 0 || w == 0) {
    set_error(state, "projective matrices are not supported");
    return false;
  }
  frame = {{values[0], values[1], values[2]}, {values[4], values[5], values[6]},
      {values[8], values[9], values[10]}, {values[12], values[13], values[14]}};
  if (w != 1) {
    frame.x /= w;
    frame.y /= w;
    frame.z /= w;
    frame.o /= w;
  }
  return true;
}

// pbrt's LookAt: camera-to-world has columns right, up, dir, eye with
// right = up x dir in pbrt's (left-handed) camera space; returns its inverse.
static bool lookat_to_frame(pbrt_state& state, const vec3f& eye, const vec3f& target,
    const vec3f& up, frame3f& frame) {
  auto dir   = target - eye;
  auto right = length(dir) > 0 && length(up) > 0 ? cross(normalize(up), normalize(dir))
                                                 : vec3f{0, 0, 0};
  if (length(right) < 1e-6f) {
    set_error(state, "the up vector is parallel to the viewing direction (or zero)");
    return false;
  }
  dir          = normalize(dir);
  right        = normalize(right);
  auto new_up  = cross(dir, right);
  auto to_world = frame3f{right, new_up, dir, eye};
  frame        = inverse(to_world, false);
  return true;
}

// Camera for the state's camera and film. pbrt's camera space has x to the
// image's right, y up, z forward; Yocto's camera looks along -z, so z flips
// and x stays: the image is pbrt's, not its mirror. The fov spans the shorter
// image side; Yocto's film (36mm) spans the longer one.
static camera_data make_pbrt_camera(const pbrt_camera_state& pcam, const vec2i& film) {
  auto camera   = camera_data{};
  auto c2w      = pcam.camera_to_world;
  camera.frame  = {safe_normalize(c2w.x), safe_normalize(c2w.y), -safe_normalize(c2w.z), c2w.o};
  camera.aspect = (float)film.x / (float)film.y;
  camera.film   = 0.036f;
  auto shorter  = camera.aspect >= 1 ? camera.film / camera.aspect : camera.film * camera.aspect;
  auto fov      = std::clamp(pcam.fov, 0.01f, 179.0f);
  camera.lens   = shorter / (2 * std::tan(radians(fov) / 2));
  camera.focus    = pcam.focus > 0 ? pcam.focus : 10000.0f;
  camera.aperture = 2 * pcam.aperture;
  return camera;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// MATERIALS
// -----------------------------------------------------------------------------
namespace yocto {

// Yocto glossy roughness (GGX alpha = roughness^2) from pbrt's roughness,
// remapped by pbrt-v4's rule alpha = sqrt(roughness) unless remapping is off.
static float pbrt_roughness_to_yocto(float roughness, bool remap) {
  auto alpha = remap ? std::sqrt(std::max(roughness, 0.0f)) : std::max(roughness, 0.0f);
  return std::clamp(std::sqrt(alpha), 0.0f, 1.0f);
}

static float get_roughness(pbrt_state& state, float default_roughness) {
  auto roughness = get_float(state, "roughness", default_roughness);
  if (find_param(state, "uroughness") || find_param(state, "vroughness")) {
    auto u    = get_float(state, "uroughness", roughness);
    auto v    = get_float(state, "vroughness", roughness);
    roughness = (u + v) / 2;
  }
  return pbrt_roughness_to_yocto(roughness, get_bool(state, "remaproughness", true));
}

// pbrt's hair material: the rows of hair_parameters that pbrt has, under
// pbrt's names, with pbrt's precedence: sigma_a, else colour, else melanin
// (one pigment given makes the other 0), else eumelanin 1.3. A value the
// material takes must lie in its row's range.
static material_data make_hair_material(pbrt_state& state) {
  struct given_parameter {
    const hair_parameter* parameter = nullptr;
    const pbrt_param*     param     = nullptr;
    vec3f                 value     = {0, 0, 0};
  };
  auto given = std::vector<given_parameter>{};
  for (auto& parameter : hair_parameters) {
    if (parameter.pbrt[0] == 0) continue;
    // Both names are looked up, so that neither is reported as ignored.
    auto param = find_param(state, parameter.pbrt);
    auto other = parameter.pbrt_alias[0] != 0 ? find_param(state, parameter.pbrt_alias) : nullptr;
    if (!param) param = other;
    if (!param) continue;
    auto value = parameter.kind == hair_parameter_kind::number
                     ? vec3f{get_float(state, param->name, 0)}
                     : get_rgb(state, param->name, {0, 0, 0});
    given.push_back({&parameter, param, value});
  }
  auto find = [&](const std::string& name) {
    for (auto i = 0; i < (int)given.size(); i++)
      if (given[i].parameter->name == name) return i;
    return -1;
  };
  // The pigment: sigma_a, else colour, else both melanins.
  auto sigma_a = find("sigma_a"), color = find("color");
  auto eumelanin = find("eumelanin"), pheomelanin = find("pheomelanin");
  auto pigment   = sigma_a >= 0 ? sigma_a : color;
  auto material  = material_data{};
  material.type  = material_type::hair;
  for (auto i = 0; i < (int)given.size(); i++) {
    auto& [parameter, param, value] = given[i];
    if (parameter->group == hair_parameter_group::pigment && pigment >= 0 && i != pigment)
      continue;
    if (!is_hair_parameter_valid(*parameter, value))
      set_error(state, "parameter " + param_decl(*param) + " must be " +
                           format_hair_parameter_range(*parameter) + ", got " +
                           format_hair_parameter_value(*parameter, value),
          param->line);
    set_hair_parameter(material.hair, *parameter, value);
  }
  if (pigment < 0 && eumelanin >= 0 && pheomelanin < 0) material.hair.pheomelanin = 0;
  if (pigment < 0 && pheomelanin >= 0 && eumelanin < 0) material.hair.eumelanin = 0;
  return material;
}

// Base colour of a material we approximate: v3's Kd or v4's reflectance.
static vec3f get_any_color(pbrt_state& state) {
  auto name = find_param(state, "Kd") ? "Kd" : "reflectance";
  return get_rgb(state, name, {0.5f, 0.5f, 0.5f});
}

// Maps a pbrt material to matte, glossy or hair; others to the nearest with a
// warning.
static material_data make_pbrt_material(pbrt_state& state, std::string_view type) {
  auto material = material_data{};
  if (type == "hair") return make_hair_material(state);
  if (type == "matte") {
    material.color = get_rgb(state, "Kd", {0.5f, 0.5f, 0.5f});
  } else if (type == "diffuse") {
    material.color = get_rgb(state, "reflectance", {0.5f, 0.5f, 0.5f});
  } else if (type == "coateddiffuse") {
    material.type      = material_type::glossy;
    material.color     = get_rgb(state, "reflectance", {0.5f, 0.5f, 0.5f});
    material.roughness = get_roughness(state, 0);
    material.ior       = get_float(state, "eta", 1.5f);
  } else if (type == "plastic") {
    material.type      = material_type::glossy;
    material.color     = get_rgb(state, "Kd", {0.25f, 0.25f, 0.25f});
    material.roughness = get_roughness(state, 0.1f);
  } else if (type == "uber" || type == "substrate" || type == "coatedconductor" ||
             type == "conductor" || type == "metal" || type == "dielectric" ||
             type == "glass" || type == "thindielectric" || type == "mirror") {
    warn_once(state, "material " + std::string{type},
        directive_name(state) + ": material \"" + std::string{type} +
            "\" is not supported; approximated by glossy");
    material.type      = material_type::glossy;
    material.color     = get_any_color(state);
    material.roughness = get_roughness(state, 0);
    for (auto i = 0; i < state.list.count; i++) state.list.items[i].used = true;
  } else {
    warn_once(state, "material " + std::string{type},
        directive_name(state) + ": material \"" + std::string{type} +
            "\" is not supported; approximated by matte");
    material.color = get_any_color(state);
    for (auto i = 0; i < state.list.count; i++) state.list.items[i].used = true;
  }
  return material;
}

// Adds the scene material for a (declared material, emission) key.
using pbrt_material_key = std::tuple<int, float, float, float>;
static std::map<pbrt_material_key, int>::iterator add_scene_material(
    pbrt_state& state, const pbrt_material_key& key) {
  auto& graphics = state.graphics;
  auto& scene    = *state.scene;
  auto  material = state.materials[graphics.material];
  material.emission = graphics.emission;
  auto name = state.material_names[graphics.material];
  if (graphics.emission != vec3f{0, 0, 0}) name += "-emission";
  for (auto& other : scene.material_names) {
    if (other == name) {
      name += "-" + std::to_string(scene.materials.size());
      break;
    }
  }
  scene.materials.push_back(material);
  scene.material_names.push_back(name);
  return state.scene_materials.emplace(key, (int)scene.materials.size() - 1).first;
}


// Scene material for the current material and area light, made on first use.
static int current_scene_material(pbrt_state& state) {
  auto& graphics = state.graphics;
  if (graphics.material == state.last_material && graphics.emission == state.last_emission)
    return state.last_scene_material;
  auto  key      = std::tuple{graphics.material, graphics.emission.x, graphics.emission.y,
      graphics.emission.z};
  auto  it       = state.scene_materials.find(key);
  if (it == state.scene_materials.end()) it = add_scene_material(state, key);
  state.last_material       = graphics.material;
  state.last_emission       = graphics.emission;
  state.last_scene_material = it->second;
  return it->second;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// LIGHTS
// -----------------------------------------------------------------------------
namespace yocto {

// Bilinear lookup with clamping at the borders.
static vec3f lookup_clamped(const texture_data& image, const vec2f& uv) {
  auto s  = std::clamp(uv.x * image.width - 0.5f, 0.0f, (float)(image.width - 1));
  auto t  = std::clamp(uv.y * image.height - 0.5f, 0.0f, (float)(image.height - 1));
  auto i  = std::min((int)s, image.width - 1), j = std::min((int)t, image.height - 1);
  auto i1 = std::min(i + 1, image.width - 1), j1 = std::min(j + 1, image.height - 1);
  auto fu = s - i, fv = t - j;
  auto at = [&](int x, int y) { return image.pixels[(size_t)y * image.width + x]; };
  return at(i, j) * (1 - fu) * (1 - fv) + at(i1, j) * fu * (1 - fv) +
         at(i, j1) * (1 - fu) * fv + at(i1, j1) * fu * fv;
}

// Resamples a pbrt-v4 equal-area octahedral map into Yocto's equirectangular
// layout in the environment's local frame (see make_environment_frame).
static texture_data equal_area_to_equirect(const texture_data& octahedral) {
  auto size  = std::max(octahedral.width, 2);
  auto image = texture_data{};
  image.width  = 2 * size;
  image.height = size;
  image.pixels.resize((size_t)image.width * image.height);
  for (auto j = 0; j < image.height; j++) {
    for (auto i = 0; i < image.width; i++) {
      auto local = equirect_to_direction(
          {(i + 0.5f) / image.width, (j + 0.5f) / image.height});
      auto pbrt_local = vec3f{local.x, local.z, local.y};
      image.pixels[(size_t)j * image.width + i] =
          lookup_clamped(octahedral, equal_area_sphere_to_square(pbrt_local));
    }
  }
  return image;
}

// pbrt's light space has z up with phi = atan2(y, x); Yocto's equirect uses y
// up with phi = atan2(z, x). Swapping the y and z axes of the light frame maps
// one onto the other, so the map's pixels keep their directions.
static frame3f make_environment_frame(const frame3f& ctm) {
  return {safe_normalize(ctm.x), safe_normalize(ctm.z), safe_normalize(ctm.y), ctm.o};
}

static vec3f get_light_scale(pbrt_state& state) {
  auto param = find_param(state, "scale");
  if (!param) return {1, 1, 1};
  return get_rgb(state, "scale", {1, 1, 1});  // v3 spectrum or v4 float
}

static bool parse_light_source(pbrt_state& state) {
  auto& scene = *state.scene;
  auto  ctm   = state.graphics.ctm;
  if (state.type == "infinite") {
    auto emission = get_rgb(state, "L", {1, 1, 1}) * get_light_scale(state);
    auto mapname  = get_string(state, "mapname", "");   // pbrt-v3, equirect
    auto filename = get_string(state, "filename", "");  // pbrt-v4, equal-area
    auto env      = environment_data{};
    env.frame     = make_environment_frame(ctm);
    env.emission  = emission;
    auto map      = !mapname.empty() ? mapname : filename;
    if (!map.empty()) {
      auto path = path_join(path_dirname(state.lexer->filename), map);
      auto ec   = std::error_code{};
      if (!std::filesystem::exists(path, ec)) {
        warn_once(state, "environment map " + map,
            directive_name(state) + ": environment map \"" + map +
                "\" not found; using a constant environment");
      } else {
        auto image = texture_data{};
        auto error = std::string{};
        if (!check_regular_file(state, path, map)) return false;
        if (!load_image(path, image, error, state.params.max_memory)) {
          set_error(state, "cannot load environment map: " + error);
          return false;
        }
        if (!filename.empty()) {
          if (image.width != image.height) {
            set_error(state, "equal-area environment map \"" + map + "\" must be square, is " +
                                 std::to_string(image.width) + "x" + std::to_string(image.height));
            return false;
          }
          // The map and its resampling coexist until the map is dropped.
          auto size = (double)std::max(image.width, 2);
          if (!check_memory(state,
                  "the scene with the equal-area map \"" + map + "\" resampled to " +
                      "equirectangular",
                  memory_in_use(state) + texture_bytes(image) + 2 * size * size * sizeof(vec3f)))
            return false;
          image = equal_area_to_equirect(image);
        }
        state.scene_bytes += texture_bytes(image);
        scene.textures.push_back(std::move(image));
        scene.texture_names.push_back(std::filesystem::path(map).stem().string());
        env.emission_tex = (int)scene.textures.size() - 1;
      }
    }
    state.scene_bytes += sizeof(environment_data) + sizeof(std::string);
    scene.environments.push_back(env);
    scene.environment_names.push_back("environment" + std::to_string(scene.environments.size()));
  } else if (state.type == "distant") {
    auto emission = get_rgb(state, "L", {1, 1, 1}) * get_light_scale(state);
    auto from     = get_array(state, "from", {"point", "point3"}, 3);
    auto to       = get_array(state, "to", {"point", "point3"}, 3);
    auto p_from   = from && from->size() == 3 ? vec3f{(*from)[0], (*from)[1], (*from)[2]}
                                              : vec3f{0, 0, 0};
    auto p_to     = to && to->size() == 3 ? vec3f{(*to)[0], (*to)[1], (*to)[2]} : vec3f{0, 0, 1};
    auto direction = safe_normalize(transform_vector(ctm, p_from - p_to));
    if (direction == vec3f{0, 0, 0}) {
      set_error(state, "\"from\" and \"to\" must differ");
      return false;
    }
    state.scene_bytes += sizeof(distant_light_data);
    scene.distant_lights.push_back({direction, emission});
  } else {
    warn_once(state, "light " + std::string{state.type},
        directive_name(state) + ": light type not supported; skipped");
    for (auto i = 0; i < state.list.count; i++) state.list.items[i].used = true;
  }
  return state.error.empty();
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// SHAPES
// -----------------------------------------------------------------------------
namespace yocto {

// Adds the shape with the current material and transform; -1 with the error
// set if the material cannot go on it (hair on a surface).
static int add_shape_instance(pbrt_state& state, shape_data&& shape, const char* kind) {
  auto& scene = *state.scene;
  // The hair BSDF has no meaning on a surface; say so at the Shape's line.
  if (!shape.triangles.empty() &&
      state.materials[state.graphics.material].type == material_type::hair) {
    set_error(state, "a hair material needs curves");
    return -1;
  }
  // An area light emits on its front (counter-clockwise) side, pbrt's
  // normal side; ReverseOrientation turns it round.
  if (state.graphics.reverse_orientation && state.graphics.emission != vec3f{0, 0, 0}) {
    for (auto& triangle : shape.triangles) std::swap(triangle.y, triangle.z);
    for (auto& normal : shape.normals) normal = -normal;
  }
  // Shapes of a fixed size (sphere, disk) are made before this check: one
  // is at most a few hundred KB over.
  auto bytes = shape_bytes(shape);
  if (!check_memory(state, "the scene with this shape", memory_in_use(state) + bytes)) return -1;
  state.scene_bytes += bytes;
  auto name = std::string{kind} + std::to_string(scene.shapes.size() + 1);
  scene.shapes.push_back(std::move(shape));
  scene.shape_names.push_back(name);
  scene.instances.push_back(
      {state.graphics.ctm, (int)scene.shapes.size() - 1, current_scene_material(state)});
  scene.instance_names.push_back(name);
  return (int)scene.shapes.size() - 1;
}

// Curve group of the current material and transform.
static pbrt_curve_group& current_curve_group(pbrt_state& state) {
  auto  material = current_scene_material(state);
  auto& ctm      = state.graphics.ctm;
  if (state.last_group >= 0 && state.last_group_material == material &&
      state.last_group_ctm == ctm)
    return state.groups[state.last_group];
  auto key = std::pair<int, std::array<float, 12>>{material,
      {ctm.x.x, ctm.x.y, ctm.x.z, ctm.y.x, ctm.y.y, ctm.y.z, ctm.z.x, ctm.z.y, ctm.z.z,
          ctm.o.x, ctm.o.y, ctm.o.z}};
  auto it = state.group_keys.find(key);
  if (it == state.group_keys.end()) {
    auto group  = pbrt_curve_group{};
    group.shape = add_shape_instance(state, shape_data{}, "curves");
    state.groups.push_back(group);
    it = state.group_keys.emplace(key, (int)state.groups.size() - 1).first;
  }
  state.last_group          = it->second;
  state.last_group_material = material;
  state.last_group_ctm      = ctm;
  return state.groups[it->second];
}

// pbrt curves: cubic Bezier (or v4 b-spline / quadratic) control points with
// widths interpolated from width0 to width1 along the whole curve.
static bool parse_curve(pbrt_state& state) {
  auto points = get_array(state, "P", {"point3", "point"}, 3);
  if (!state.error.empty()) return false;
  if (!points) {
    set_error(state, "missing parameter \"point3 P\"");
    return false;
  }
  auto width  = get_float(state, "width", 1);
  auto width0 = get_float(state, "width0", width);
  auto width1 = get_float(state, "width1", width);
  auto type   = get_string(state, "type", "flat");
  auto basis  = get_string(state, "basis", "bezier");
  auto degree = get_int(state, "degree", 3);
  if (!state.error.empty()) return false;
  if (!(width0 >= 0 && width1 >= 0)) {
    set_error(state, "curve widths must be non-negative");
    return false;
  }
  if (type == "ribbon") {
    find_param(state, "N");
    warn_once(state, "ribbon", directive_name(state) +
                                   ": ribbon normals are ignored; curves are rendered round");
  } else if (type != "flat" && type != "cylinder") {
    set_error(state, "unknown curve type \"" + type + "\"");
    return false;
  }
  if ((basis != "bezier" && basis != "bspline") || (degree != 2 && degree != 3)) {
    set_error(state,
        "unsupported curve basis \"" + basis + "\" of degree " + std::to_string(degree));
    return false;
  }
  // Control points as cubic Bezier segments.
  auto  num_points = (int)points->size() / 3;
  auto  cp         = [&](int i) {
    return vec3f{(*points)[3 * i], (*points)[3 * i + 1], (*points)[3 * i + 2]};
  };
  auto& segments = state.segments;
  segments.clear();
  if (basis == "bezier" && degree == 3) {
    if (num_points < 4 || (num_points - 1) % 3 != 0) {
      set_error(state, "a cubic Bezier curve needs 4 + 3n control points, got " +
                           std::to_string(num_points));
      return false;
    }
    for (auto i = 0; i + 3 < num_points; i += 3)
      segments.push_back({cp(i), cp(i + 1), cp(i + 2), cp(i + 3)});
  } else if (basis == "bezier") {
    if (num_points < 3 || (num_points - 1) % 2 != 0) {
      set_error(state, "a quadratic Bezier curve needs 3 + 2n control points, got " +
                           std::to_string(num_points));
      return false;
    }
    // Degree elevation: q1 = p0/3 + 2p1/3, q2 = 2p1/3 + p2/3.
    for (auto i = 0; i + 2 < num_points; i += 2)
      segments.push_back({cp(i), (cp(i) + 2.0f * cp(i + 1)) / 3.0f,
          (2.0f * cp(i + 1) + cp(i + 2)) / 3.0f, cp(i + 2)});
  } else {
    if (num_points < degree + 1) {
      set_error(state, "a b-spline of degree " + std::to_string(degree) + " needs at least " +
                           std::to_string(degree + 1) + " control points, got " +
                           std::to_string(num_points));
      return false;
    }
    // Uniform b-spline segments in Bezier form (Boehm's knot insertion).
    for (auto i = 0; i + degree < num_points; i++) {
      if (degree == 3) {
        auto p0 = cp(i), p1 = cp(i + 1), p2 = cp(i + 2), p3 = cp(i + 3);
        segments.push_back({(p0 + 4.0f * p1 + p2) / 6.0f, (2.0f * p1 + p2) / 3.0f,
            (p1 + 2.0f * p2) / 3.0f, (p1 + 4.0f * p2 + p3) / 6.0f});
      } else {
        auto q0 = (cp(i) + cp(i + 1)) / 2.0f, q1 = cp(i + 1), q2 = (cp(i + 1) + cp(i + 2)) / 2.0f;
        segments.push_back({q0, (q0 + 2.0f * q1) / 3.0f, (2.0f * q1 + q2) / 3.0f, q2});
      }
    }
  }
  // Append to the group's shape, chaining onto the previous curve's end; the
  // directive's end checks the new total against the budget.
  auto& group = current_curve_group(state);
  if (group.shape < 0) return false;
  auto& shape = state.scene->shapes[group.shape];
  auto  count = (int)segments.size();
  state.scene_bytes +=
      (double)count * (3 * (sizeof(vec3f) + sizeof(float)) + sizeof(vec4i)) +
      sizeof(vec3f) + sizeof(float);
  for (auto s = 0; s < count; s++) {
    auto& b      = segments[s];
    auto  radius = [&](int k) {
      auto t = (s + k / 3.0f) / count;
      return ((1 - t) * width0 + t * width1) / 2;
    };
    auto first = -1;
    if (group.last_vertex >= 0 && shape.positions[group.last_vertex] == b[0]) {
      first = group.last_vertex;
    } else {
      first = (int)shape.positions.size();
      shape.positions.push_back(b[0]);
      shape.radius.push_back(radius(0));
    }
    auto base = (int)shape.positions.size();
    for (auto k = 1; k < 4; k++) {
      shape.positions.push_back(b[k]);
      shape.radius.push_back(radius(k));
    }
    shape.curves.push_back({first, base, base + 1, base + 2});
    group.last_vertex = base + 2;
  }
  return true;
}

static shape_data make_disk_shape(float radius, float inner, float height, int steps = 64) {
  auto shape = shape_data{};
  auto ring  = [&](float r) {
    auto start = (int)shape.positions.size();
    for (auto i = 0; i < steps; i++) {
      auto phi = 2 * pif * i / steps;
      auto p   = vec3f{r * std::cos(phi), r * std::sin(phi), height};
      shape.positions.push_back(p);
      shape.normals.push_back({0, 0, 1});
      shape.texcoords.push_back({(float)i / steps, radius > 0 ? 1 - r / radius : 0});
    }
    return start;
  };
  if (inner <= 0) {
    shape.positions.push_back({0, 0, height});
    shape.normals.push_back({0, 0, 1});
    shape.texcoords.push_back({0, 1});
    auto outer = ring(radius);
    for (auto i = 0; i < steps; i++)
      shape.triangles.push_back({0, outer + i, outer + (i + 1) % steps});
  } else {
    auto in = ring(inner), out = ring(radius);
    for (auto i = 0; i < steps; i++) {
      auto next = (i + 1) % steps;
      shape.triangles.push_back({in + i, out + i, out + next});
      shape.triangles.push_back({in + i, out + next, in + next});
    }
  }
  return shape;
}

static bool parse_triangle_mesh(pbrt_state& state) {
  auto indices  = get_array(state, "indices", {"integer"}, 3);
  auto points   = get_array(state, "P", {"point3", "point"}, 3);
  auto normals  = get_array(state, "N", {"normal", "normal3"}, 3);
  auto uv_param = find_param(state, "uv") ? "uv" : "st";
  auto uvs      = get_array(state, uv_param, {"float", "point2"}, 2);
  if (!state.error.empty()) return false;
  if (!points) {
    set_error(state, "missing parameter \"point3 P\"");
    return false;
  }
  // The mesh is checked against the budget before it is built, at its
  // final size (no growth by doubling).
  auto num_vertices  = (int)points->size() / 3;
  auto num_triangles = indices ? indices->size() / 3 : (size_t)1;
  auto vertex_bytes  = sizeof(vec3f) + (normals ? sizeof(vec3f) : 0) + (uvs ? sizeof(vec2f) : 0);
  if (!check_memory(state, "the scene with this mesh",
          memory_in_use(state) + (double)num_vertices * vertex_bytes +
              (double)num_triangles * sizeof(vec3i)))
    return false;
  auto shape = shape_data{};
  shape.positions.reserve(num_vertices);
  shape.triangles.reserve(num_triangles);
  for (auto i = 0; i < num_vertices; i++)
    shape.positions.push_back({(*points)[3 * i], (*points)[3 * i + 1], (*points)[3 * i + 2]});
  if (indices) {
    for (auto i = 0; i + 2 < (int)indices->size(); i += 3) {
      auto t = vec3i{(int)(*indices)[i], (int)(*indices)[i + 1], (int)(*indices)[i + 2]};
      for (auto k = 0; k < 3; k++) {
        if (t[k] < 0 || t[k] >= num_vertices) {
          set_error(state, "index " + std::to_string(t[k]) + " of triangle " +
                               std::to_string(i / 3) + " is out of range (" +
                               std::to_string(num_vertices) + " vertices)");
          return false;
        }
      }
      shape.triangles.push_back(t);
    }
  } else if (num_vertices == 3) {
    shape.triangles.push_back({0, 1, 2});
  } else {
    set_error(state, "missing parameter \"integer indices\"");
    return false;
  }
  if (normals) {
    if ((int)normals->size() / 3 != num_vertices) {
      set_error(state, "\"N\" has " + std::to_string(normals->size() / 3) +
                           " normals for " + std::to_string(num_vertices) + " vertices");
      return false;
    }
    shape.normals.reserve(num_vertices);
    for (auto i = 0; i < num_vertices; i++)
      shape.normals.push_back(safe_normalize(
          vec3f{(*normals)[3 * i], (*normals)[3 * i + 1], (*normals)[3 * i + 2]}));
  }
  if (uvs) {
    if ((int)uvs->size() / 2 != num_vertices) {
      set_error(state, "\"" + std::string{uv_param} + "\" has " +
                           std::to_string(uvs->size() / 2) + " pairs for " +
                           std::to_string(num_vertices) + " vertices");
      return false;
    }
    shape.texcoords.reserve(num_vertices);
    for (auto i = 0; i < num_vertices; i++)
      shape.texcoords.push_back({(*uvs)[2 * i], (*uvs)[2 * i + 1]});
  }
  add_shape_instance(state, std::move(shape), "mesh");
  return state.error.empty();
}

static bool parse_shape(pbrt_state& state) {
  auto& type = state.type;
  if (type == "curve") return parse_curve(state);
  if (type == "sphere") {
    auto radius = get_float(state, "radius", 1);
    if (!state.error.empty()) return false;
    if (!(radius > 0)) {
      set_error(state, "radius must be positive");
      return false;
    }
    add_shape_instance(state, make_sphere_shape(64, radius), "sphere");
  } else if (type == "disk") {
    auto radius = get_float(state, "radius", 1);
    auto inner  = get_float(state, "innerradius", 0);
    auto height = get_float(state, "height", 0);
    if (!state.error.empty()) return false;
    if (!(radius > 0) || !(inner >= 0 && inner < radius)) {
      set_error(state, "radius must be positive and innerradius in [0, radius)");
      return false;
    }
    add_shape_instance(state, make_disk_shape(radius, inner, height), "disk");
  } else if (type == "trianglemesh") {
    return parse_triangle_mesh(state);
  } else if (type == "plymesh") {
    auto filename = get_string(state, "filename", "");
    if (!state.error.empty()) return false;
    if (filename.empty()) {
      set_error(state, "missing parameter \"string filename\"");
      return false;
    }
    auto path  = path_join(path_dirname(state.lexer->filename), filename);
    auto shape = shape_data{};
    auto error = std::string{};
    if (!check_regular_file(state, path, filename)) return false;
    if (!load_shape(path, shape, error, state.params.max_memory)) {
      set_error(state, error);
      return false;
    }
    add_shape_instance(state, std::move(shape), "ply");
  } else {
    warn_once(state, "shape " + std::string{type},
        directive_name(state) + ": shape type not supported; skipped");
    for (auto i = 0; i < state.list.count; i++) state.list.items[i].used = true;
  }
  return state.error.empty();
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// DIRECTIVES
// -----------------------------------------------------------------------------
namespace yocto {

static bool parse_pbrt_file(pbrt_state& state, const std::string& filename, int depth);

static bool parse_include(pbrt_state& state) {
  auto name = std::string_view{};
  if (!parse_string(state, name, "a file name")) return false;
  auto path = path_join(path_dirname(state.lexer->filename), std::string{name});
  auto ec   = std::error_code{};
  auto canonical = std::filesystem::weakly_canonical(path, ec).string();
  if (ec) canonical = path;
  for (auto& open : state.open_files) {
    if (open == canonical) {
      set_error(state, "include cycle: \"" + std::string{name} + "\" is already being read");
      return false;
    }
  }
  if (!check_regular_file(state, path, std::string{name})) return false;
  // The included file's directives report their own file and line.
  auto saved = std::tuple{state.lexer, state.directive, state.type, state.line};
  if (!parse_pbrt_file(state, path, (int)state.open_files.size())) return false;
  std::tie(state.lexer, state.directive, state.type, state.line) = saved;
  return true;
}

static bool parse_begin_end(pbrt_state& state, std::string_view directive) {
  if (directive == "AttributeBegin" || directive == "TransformBegin") {
    state.stack.push_back({state.graphics, directive == "AttributeBegin", state.line});
    return true;
  }
  auto attribute = directive == "AttributeEnd";
  if (state.stack.empty()) {
    set_error(state, "no matching " + std::string{attribute ? "AttributeBegin" : "TransformBegin"});
    return false;
  }
  auto& top = state.stack.back();
  if (top.attribute != attribute) {
    set_error(state, "mismatched block: opened by " +
                         std::string{top.attribute ? "AttributeBegin" : "TransformBegin"} +
                         " at line " + std::to_string(top.line));
    return false;
  }
  if (attribute) {
    state.graphics = top.graphics;
  } else {
    state.graphics.ctm = top.graphics.ctm;
  }
  state.stack.pop_back();
  return true;
}

static bool parse_transform(pbrt_state& state, std::string_view directive) {
  auto& ctm = state.graphics.ctm;
  float v[16];
  if (directive == "Translate") {
    if (!parse_numbers(state, v, 3)) return false;
    ctm = ctm * translation_frame({v[0], v[1], v[2]});
  } else if (directive == "Scale") {
    if (!parse_numbers(state, v, 3)) return false;
    ctm = ctm * scaling_frame({v[0], v[1], v[2]});
  } else if (directive == "Rotate") {
    if (!parse_numbers(state, v, 4)) return false;
    if (vec3f{v[1], v[2], v[3]} == vec3f{0, 0, 0}) {
      set_error(state, "the rotation axis is zero");
      return false;
    }
    ctm = ctm * rotation_frame({v[1], v[2], v[3]}, radians(v[0]));
  } else if (directive == "LookAt") {
    if (!parse_numbers(state, v, 9)) return false;
    auto frame = frame3f{};
    if (!lookat_to_frame(state, {v[0], v[1], v[2]}, {v[3], v[4], v[5]}, {v[6], v[7], v[8]}, frame))
      return false;
    ctm = ctm * frame;
  } else if (directive == "Transform" || directive == "ConcatTransform") {
    auto frame = frame3f{};
    if (!parse_numbers(state, v, 16) || !matrix_to_frame(state, v, frame)) return false;
    ctm = directive == "Transform" ? frame : ctm * frame;
  } else if (directive == "Identity") {
    ctm = identity3x4f;
  } else if (directive == "CoordinateSystem") {
    auto name = std::string_view{};
    if (!parse_string(state, name, "a name")) return false;
    state.coordinate_systems[std::string{name}] = ctm;
  } else if (directive == "CoordSysTransform") {
    auto name = std::string_view{};
    if (!parse_string(state, name, "a name")) return false;
    auto it = state.coordinate_systems.find(std::string{name});
    if (it == state.coordinate_systems.end()) {
      set_error(state, "unknown coordinate system \"" + std::string{name} + "\"");
      return false;
    }
    ctm = it->second;
  }
  if (!is_finite(ctm)) {
    set_error(state, "the transform is not finite");
    return false;
  }
  return true;
}

static bool parse_camera(pbrt_state& state) {
  if (!parse_params(state)) return false;
  if (state.type != "perspective") {
    warn_once(state, "camera", directive_name(state) +
                                   ": only perspective cameras are supported; using one");
  }
  auto det = glm::determinant(frame_rotation(state.graphics.ctm));
  if (!(std::abs(det) > 1e-12f)) {
    set_error(state, "the camera transform is singular");
    return false;
  }
  auto& camera           = state.camera;
  camera.camera_to_world = inverse(state.graphics.ctm);
  camera.fov             = get_float(state, "fov", 90);
  camera.focus           = get_float(state, "focaldistance", 0);
  camera.aperture        = get_float(state, "lensradius", 0);
  state.has_camera       = true;
  state.coordinate_systems["camera"] = camera.camera_to_world;
  if (!(camera.fov > 0 && camera.fov < 180)) set_error(state, "fov must be in (0, 180) degrees");
  return state.error.empty();
}

// One directive; the directive name has been read.
static bool parse_directive(pbrt_state& state, std::string_view directive) {
  auto& scene      = *state.scene;
  state.type       = {};
  state.list.count = 0;
  auto with_type = [&](const char* what) { return parse_string(state, state.type, what); };
  if (directive == "Shape") {
    if (!with_type("a shape type") || !parse_params(state) || !parse_shape(state)) return false;
  } else if (directive == "AttributeBegin" || directive == "AttributeEnd" ||
             directive == "TransformBegin" || directive == "TransformEnd") {
    if (!parse_begin_end(state, directive)) return false;
  } else if (directive == "Translate" || directive == "Scale" || directive == "Rotate" ||
             directive == "LookAt" || directive == "Transform" ||
             directive == "ConcatTransform" || directive == "Identity" ||
             directive == "CoordinateSystem" || directive == "CoordSysTransform") {
    if (!parse_transform(state, directive)) return false;
  } else if (directive == "Include" || directive == "Import") {
    if (!parse_include(state)) return false;
    // The list holds the included file's last parameters, whose names point
    // into its text, freed by now: Include has none of its own to check.
    state.list.count = 0;
  } else if (directive == "Material") {
    if (!with_type("a material type") || !parse_params(state)) return false;
    auto material = make_pbrt_material(state, state.type);
    state.materials.push_back(material);
    state.material_names.push_back(std::string{state.type});
    state.graphics.material = (int)state.materials.size() - 1;
  } else if (directive == "MakeNamedMaterial") {
    auto name = std::string_view{};
    if (!parse_string(state, name, "a material name") || !parse_params(state)) return false;
    auto type = get_string(state, "type", "");
    if (type.empty()) {
      set_error(state, "MakeNamedMaterial \"" + std::string{name} +
                           "\" needs a \"string type\" parameter");
      return false;
    }
    auto material = make_pbrt_material(state, type);
    state.materials.push_back(material);
    state.material_names.push_back(std::string{name});
    // Once per name: warnings of an Include read many times stay few.
    if (state.named_materials.count(std::string{name}))
      warn_once(state, "redefined " + std::string{name},
          "MakeNamedMaterial: \"" + std::string{name} + "\" redefined");
    state.named_materials[std::string{name}] = (int)state.materials.size() - 1;
  } else if (directive == "NamedMaterial") {
    auto name = std::string_view{};
    if (!parse_string(state, name, "a material name")) return false;
    auto it = state.named_materials.find(std::string{name});
    if (it == state.named_materials.end()) {
      set_error(state, "unknown material \"" + std::string{name} + "\"");
      return false;
    }
    state.graphics.material = it->second;
  } else if (directive == "Texture") {
    auto name = std::string_view{}, type = std::string_view{};
    if (!parse_string(state, name, "a texture name") ||
        !parse_string(state, type, "a texture type") || !with_type("a texture class") ||
        !parse_params(state))
      return false;
    auto texture = pbrt_texture{};
    if (state.type == "constant") {
      texture.constant = true;
      texture.value    = get_rgb(state, "value", {1, 1, 1});
    } else {
      for (auto i = 0; i < state.list.count; i++) state.list.items[i].used = true;
    }
    state.textures[std::string{name}] = texture;
  } else if (directive == "LightSource") {
    if (!with_type("a light type") || !parse_params(state) || !parse_light_source(state))
      return false;
  } else if (directive == "AreaLightSource") {
    if (!with_type("an area light type") || !parse_params(state)) return false;
    if (state.type == "diffuse") {
      state.graphics.emission = get_rgb(state, "L", {1, 1, 1}) * get_light_scale(state);
      if (get_bool(state, "twosided", false))
        warn_once(state, "twosided", directive_name(state) +
                                         ": twosided area lights emit from the front side only");
    } else {
      warn_once(state, "arealight", directive_name(state) + ": area light type not supported");
      for (auto i = 0; i < state.list.count; i++) state.list.items[i].used = true;
    }
  } else if (directive == "Camera") {
    if (!with_type("a camera type") || !parse_camera(state)) return false;
  } else if (directive == "Film") {
    if (!with_type("a film type") || !parse_params(state)) return false;
    auto v3          = state.type == "image";
    state.film.x     = get_int(state, "xresolution", v3 ? 640 : 1280);
    state.film.y     = get_int(state, "yresolution", v3 ? 480 : 720);
    state.has_film   = true;
    get_string(state, "filename", "");  // the output name is the user's choice
    if (state.film.x <= 0 || state.film.y <= 0 || state.film.x > 1 << 16 ||
        state.film.y > 1 << 16)
      set_error(state, "resolution must be in [1, 65536]");
    scene.settings.resolution = std::max(state.film.x, state.film.y);
  } else if (directive == "Sampler") {
    if (!with_type("a sampler type") || !parse_params(state)) return false;
    auto samples = get_int(state, "pixelsamples", 0);
    if (samples < 0) set_error(state, "pixelsamples must be positive");
    if (samples > 0) scene.settings.samples = samples;
  } else if (directive == "Integrator") {
    if (!with_type("an integrator type") || !parse_params(state)) return false;
    auto bounces = get_int(state, "maxdepth", -1);
    if (bounces >= 0) scene.settings.bounces = bounces;
  } else if (directive == "WorldBegin") {
    state.graphics.ctm               = identity3x4f;
    state.coordinate_systems["world"] = identity3x4f;
    state.world_begun                 = true;
  } else if (directive == "ReverseOrientation") {
    state.graphics.reverse_orientation = !state.graphics.reverse_orientation;
  } else if (directive == "WorldEnd") {
    // Nothing to do: the end of the file ends the world.
  } else if (directive == "ActiveTransform") {
    auto token = pbrt_token{};
    if (!next_token(*state.lexer, token, state.error)) return false;
    if (token.kind != pbrt_token_kind::word ||
        (token.text != "All" && token.text != "StartTime" && token.text != "EndTime")) {
      set_error(state, "expected All, StartTime or EndTime, got " + token_description(token));
      return false;
    }
    if (token.text != "All")
      warn_once(state, "motion", "ActiveTransform: motion blur is not supported; "
                                 "the transforms apply at all times");
  } else if (directive == "PixelFilter" || directive == "Accelerator" ||
             directive == "TransformTimes" || directive == "Option" ||
             directive == "ColorSpace" || directive == "MakeNamedMedium" ||
             directive == "MediumInterface" || directive == "Attribute") {
    warn_once(state, "directive " + std::string{directive},
        std::string{directive} + ": directive ignored");
    return skip_arguments(state);
  } else if (state.params.lenient) {
    warn_once(state, "unknown directive " + std::string{directive},
        "unknown directive " + std::string{directive} + " skipped");
    return skip_arguments(state);
  } else {
    set_error(state, "unknown directive (use --lenient to skip it)");
    return false;
  }
  if (!state.error.empty()) return false;
  warn_unused_params(state);
  return true;
}

// The text read for one scene, with every Include, is bounded by 4 times the
// memory budget. Real curve files hold about 3.5 bytes of text per byte of
// scene, and a scene must leave room for its BVH, so a scene that renders
// has less text than that; more can only come from Includes repeated over
// and over (8 Includes in each of 11 files are 8^10 parses). An Include
// counts as at least 1 MiB, so a tree of tiny files stops within seconds too:
// resolving, opening and mapping a file takes some 25 us, as long as parsing
// a few MiB of text.
const auto max_text_per_budget = 4.0;
const auto min_include_bytes   = 1024.0 * 1024;

static bool parse_pbrt_file(pbrt_state& state, const std::string& filename, int depth) {
  // Errors of the file as a whole name the including directive too, if any.
  auto fail = [&](const std::string& error) {
    if (state.lexer) {
      set_error(state, error);
    } else {
      state.error = error;
    }
    return false;
  };
  if (depth > 64) {
    set_error(state, "includes nested too deeply");
    return false;
  }
  auto error = std::string{};
  auto size  = (size_t)0;
  auto fd    = open_regular_file(filename, size, error);
  if (fd < 0) return fail(error);
  auto lexer     = pbrt_lexer{};
  lexer.filename = filename;
  auto mapping   = pbrt_file_mapping{};
  if (map_file(fd, size, filename, mapping)) {
    close(fd);
    lexer.ptr = (const char*)mapping.data;
    lexer.end = lexer.ptr + mapping.size;
  } else {
    if (!read_open_file(fd, size, filename, lexer.data, error, memory_in_use(state),
            state.params.max_memory))
      return fail(error);
    lexer.ptr = lexer.data.data();
    lexer.end = lexer.data.data() + lexer.data.size();
  }
  state.parsed_bytes += std::max((double)(lexer.end - lexer.ptr), min_include_bytes);
  auto max_parsed = max_text_per_budget * state.params.max_memory;
  if (state.parsed_bytes > max_parsed)
    return fail(filename + ": the scene's text with its Includes comes to over " +
                std::to_string((long long)(max_parsed / (1 << 20))) + " MiB, " +
                std::to_string((int)max_text_per_budget) +
                " times the memory limit (--max-memory; an Include counts as at least " +
                std::to_string((int)(min_include_bytes / (1 << 20))) + " MiB)");
  auto text_bytes = (double)lexer.data.capacity();
  state.text_bytes += text_bytes;
  auto ec        = std::error_code{};
  auto canonical = std::filesystem::weakly_canonical(filename, ec).string();
  state.open_files.push_back(ec ? filename : canonical);
  state.lexer = &lexer;
  auto token  = pbrt_token{};
  while (true) {
    if (!next_token(lexer, token, state.error)) return false;
    if (token.kind == pbrt_token_kind::eof) break;
    state.lexer     = &lexer;
    state.line      = token.line;
    state.directive = token.text;
    state.type      = {};
    if (token.kind != pbrt_token_kind::word) {
      state.directive = "";
      state.error     = location(state) + "expected a directive, got " + token_description(token);
      return false;
    }
    auto parsed = false;
    try {
      parsed = parse_directive(state, token.text);
    } catch (const std::bad_alloc&) {
      // Named where it happened: the innermost file, line and directive.
      if (state.error.empty())
        state.error = allocation_error(
            state.lexer->filename + ":" + std::to_string(state.line), directive_name(state));
    }
    if (!parsed) {
      if (state.error.empty()) set_error(state, "cannot parse directive");
      return false;
    }
    // The world (and what it Includes) is never read for a camera.
    if (state.camera_only && state.world_begun) break;
    // What the directive added, within the budget.
    auto memory = memory_in_use(state);
    if (memory > state.params.max_memory && !check_memory(state, "the scene", memory))
      return false;
  }
  state.open_files.pop_back();
  state.text_bytes -= text_bytes;
  return true;
}

static bool load_pbrt_scene(const std::string& filename, scene_data& scene,
    std::string& error, const pbrt_params& params, std::vector<std::string>* warnings,
    bool camera_only) try {
  scene       = {};
  auto state  = pbrt_state{};
  state.scene = &scene;
  state.params      = params;
  state.warnings    = warnings;
  state.camera_only = camera_only;
  // pbrt's default material is a grey diffuse.
  state.materials.push_back(material_data{material_type::matte, {0, 0, 0}, {0.5f, 0.5f, 0.5f}});
  state.material_names.push_back("default");
  if (!parse_pbrt_file(state, filename, 0)) {
    error = state.error;
    scene = {};
    return false;
  }
  if (camera_only && !state.world_begun) {
    error = filename + ": no WorldBegin";
    scene = {};
    return false;
  }
  if (!state.stack.empty()) {
    add_warning(state, filename + ": " + std::to_string(state.stack.size()) +
                           " unclosed AttributeBegin/TransformBegin block(s)");
  }
  // An empty file, or one whose world is missing, would render black.
  if (scene.shapes.empty() && scene.environments.empty() && !params.allow_empty) {
    error = filename + ": nothing to render: no shapes and no environment light";
    scene = {};
    return false;
  }
  // Without a Film directive, pbrt-v3's default 640x480 gives the aspect; the
  // resolution stays unset for the renderer to choose.
  auto film = state.has_film ? state.film : vec2i{640, 480};
  scene.cameras.push_back(make_pbrt_camera(state.camera, film));
  scene.camera_names.push_back("camera");
  if (params.curves_as_lines) {
    auto segments = std::max(params.segments, 1);
    for (auto& shape : scene.shapes) {
      if (shape.curves.empty()) continue;
      // Each curve gives `segments` lines and at most `segments` + 1
      // vertices; the curves are dropped once converted.
      auto curves = (double)shape.curves.size();
      auto lines  = curves * segments * sizeof(vec2i) +
                   curves * (segments + 1) * (sizeof(vec3f) + sizeof(float));
      if (!check_load_memory(filename,
              "the scene with curves as lines (" + std::to_string(segments) + " segments each)",
              memory_in_use(state) + lines, params.max_memory, error)) {
        scene = {};
        return false;
      }
      state.scene_bytes -= shape_bytes(shape);
      shape = curves_to_lines(shape, segments);
      state.scene_bytes += shape_bytes(shape);
    }
  }
  return validate_loaded_scene(scene, filename, error);
} catch (const std::bad_alloc&) {
  // Past the budget's checks, the system (or ulimit -v) gave less.
  error = allocation_error(filename, "the scene");
  return false;
}

bool load_pbrt_scene(const std::string& filename, scene_data& scene, std::string& error,
    const pbrt_params& params, std::vector<std::string>* warnings) {
  return load_pbrt_scene(filename, scene, error, params, warnings, false);
}

bool load_pbrt_camera(const std::string& filename, camera_data& camera, std::string& error,
    const pbrt_params& params, std::vector<std::string>* warnings) {
  auto scene                = scene_data{};
  auto camera_params        = params;
  camera_params.allow_empty = true;  // the world is not read: a camera alone
  if (!load_pbrt_scene(filename, scene, error, camera_params, warnings, true)) return false;
  camera = scene.cameras.front();
  return true;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// PBRT CURVES
// -----------------------------------------------------------------------------
namespace yocto {

bool save_pbrt_curves(const std::string& filename, const shape_data& shape,
    std::string& error) {
  auto gzipped = filename.size() > 3 && filename.substr(filename.size() - 3) == ".gz";
  // Through fileio's checked temporary; zlib writes into a duplicate of its
  // descriptor, so that finishing can still flush and measure the file.
  auto output = output_file{};
  if (!open_output_file(output, filename, error)) return false;
  auto descriptor = dup(output.descriptor);
  auto file = descriptor >= 0 ? gzdopen(descriptor, gzipped ? "wb6" : "wbT") : nullptr;
  if (!file) {
    if (descriptor >= 0) close(descriptor);
    discard_output_file(output);
    return error = filename + ": cannot open for writing", false;
  }
  auto ok   = true;
  auto line = std::string{};
  char buffer[512];
  auto write = [&](const char* text, int size) {
    if (ok && gzwrite(file, text, size) != size) ok = false;
  };
  auto header = std::string("# hair curves written by yocto-hair's generator\n");
  write(header.data(), (int)header.size());
  for (auto& curve : shape.curves) {
    auto& p = shape.positions;
    auto  r = [&](int i) { return shape.radius.empty() ? 0.0f : shape.radius[i]; };
    auto size = std::snprintf(buffer, sizeof(buffer),
        "Shape \"curve\" \"string type\" \"cylinder\" \"point3 P\" [ %.7g %.7g %.7g %.7g %.7g "
        "%.7g %.7g %.7g %.7g %.7g %.7g %.7g ] \"float width0\" %.7g \"float width1\" %.7g\n",
        p[curve.x].x, p[curve.x].y, p[curve.x].z, p[curve.y].x, p[curve.y].y, p[curve.y].z,
        p[curve.z].x, p[curve.z].y, p[curve.z].z, p[curve.w].x, p[curve.w].y, p[curve.w].z,
        2 * r(curve.x), 2 * r(curve.w));
    write(buffer, size);
  }
  if (gzclose(file) != Z_OK) ok = false;
  // The bytes went through zlib's descriptor: the size check counts them.
  auto status = (struct stat){};
  if (ok && fstat(output.descriptor, &status) == 0) output.written = (size_t)status.st_size;
  if (!ok) {
    discard_output_file(output);
    return error = filename + ": cannot write file", false;
  }
  if (!commit_output_file(output, error)) return false;
  return true;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// MAPPINGS
// -----------------------------------------------------------------------------
namespace yocto {

// Clarberg 2008: the sphere's upper hemisphere fills the inner diamond
// |u| + |v| <= 1, the lower one the four outer triangles; r = sqrt(1 - |z|)
// and the angle in the quadrant is proportional to the position along the
// diamond's edge, which makes the mapping area-preserving.
vec2f equal_area_sphere_to_square(const vec3f& d) {
  auto ax = std::abs(d.x), ay = std::abs(d.y), az = std::abs(d.z);
  auto r   = safe_sqrt(1 - az);
  auto a   = std::max(ax, ay), b = std::min(ax, ay);
  auto phi = a > 0 ? std::atan(b / a) * 2 / pif : 0.0f;  // in [0, 1]
  if (ax < ay) phi = 1 - phi;
  auto v = phi * r;
  auto u = r - v;
  if (d.z < 0) {
    std::swap(u, v);
    u = 1 - u;
    v = 1 - v;
  }
  u = std::copysign(u, d.x);
  v = std::copysign(v, d.y);
  return {(u + 1) / 2, (v + 1) / 2};
}

vec3f equal_area_square_to_sphere(const vec2f& uv) {
  auto u = 2 * uv.x - 1, v = 2 * uv.y - 1;
  auto au = std::abs(u), av = std::abs(v);
  auto signed_distance = 1 - (au + av);  // > 0 in the upper hemisphere
  auto r   = 1 - std::abs(signed_distance);
  auto phi = (r == 0 ? 1 : (av - au) / r + 1) * pif / 4;
  auto z   = std::copysign(1 - r * r, signed_distance);
  auto s   = r * safe_sqrt(2 - r * r);
  return {std::copysign(std::cos(phi), u) * s, std::copysign(std::sin(phi), v) * s, z};
}

}  // namespace yocto
