//
// Implementation of Yocto/PLY: see yocto_ply.h.
//

#include "yocto_ply.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <new>
#include <string_view>
#include <unordered_map>

// -----------------------------------------------------------------------------
// PLY SHAPES
// -----------------------------------------------------------------------------
namespace yocto {

enum struct ply_format { ascii, binary_little_endian, binary_big_endian };
enum struct ply_type { i8, u8, i16, u16, i32, u32, f32, f64 };

struct ply_property {
  std::string name       = "";
  ply_type    type       = ply_type::f32;
  bool        is_list    = false;
  ply_type    count_type = ply_type::u8;
};

struct ply_element {
  std::string               name       = "";
  size_t                    count      = 0;
  std::vector<ply_property> properties = {};
};

// Where reading is in the data; `line` counts lines for ascii messages.
struct ply_cursor {
  const char* data      = nullptr;
  size_t      size      = 0;
  size_t      pos       = 0;
  int         line      = 1;
  ply_format  format    = ply_format::ascii;
  bool        bad_token = false;  // an ascii token that is not a number
  std::string token     = "";     // that token, for the message
};

static bool parse_ply_type(const std::string& name, ply_type& type) {
  static const auto names = std::unordered_map<std::string, ply_type>{
      {"char", ply_type::i8}, {"int8", ply_type::i8}, {"uchar", ply_type::u8},
      {"uint8", ply_type::u8}, {"short", ply_type::i16}, {"int16", ply_type::i16},
      {"ushort", ply_type::u16}, {"uint16", ply_type::u16}, {"int", ply_type::i32},
      {"int32", ply_type::i32}, {"uint", ply_type::u32}, {"uint32", ply_type::u32},
      {"float", ply_type::f32}, {"float32", ply_type::f32},
      {"double", ply_type::f64}, {"float64", ply_type::f64}};
  auto found = names.find(name);
  if (found == names.end()) return false;
  type = found->second;
  return true;
}

static size_t ply_type_size(ply_type type) {
  switch (type) {
    case ply_type::i8:
    case ply_type::u8: return 1;
    case ply_type::i16:
    case ply_type::u16: return 2;
    case ply_type::i32:
    case ply_type::u32:
    case ply_type::f32: return 4;
    case ply_type::f64: return 8;
  }
  return 1;
}

// Loads a value of type T stored with the given byte order.
template <typename T>
static inline T load_raw(const char* ptr, bool swap) {
  auto value = T{};
  if (!swap) {
    std::memcpy(&value, ptr, sizeof(T));
  } else {
    char bytes[sizeof(T)];
    for (size_t k = 0; k < sizeof(T); k++) bytes[k] = ptr[sizeof(T) - 1 - k];
    std::memcpy(&value, bytes, sizeof(T));
  }
  return value;
}

static inline double load_binary_value(const char* ptr, ply_type type, bool swap) {
  switch (type) {
    case ply_type::i8: return load_raw<int8_t>(ptr, swap);
    case ply_type::u8: return load_raw<uint8_t>(ptr, swap);
    case ply_type::i16: return load_raw<int16_t>(ptr, swap);
    case ply_type::u16: return load_raw<uint16_t>(ptr, swap);
    case ply_type::i32: return load_raw<int32_t>(ptr, swap);
    case ply_type::u32: return load_raw<uint32_t>(ptr, swap);
    case ply_type::f32: return load_raw<float>(ptr, swap);
    case ply_type::f64: return load_raw<double>(ptr, swap);
  }
  return 0;
}

static bool swap_bytes(ply_format format) {
  return format == (host_little_endian ? ply_format::binary_big_endian
                                       : ply_format::binary_little_endian);
}

// Reads the next value; false at the end of the data or, for ascii, on a
// token that is not a number (bad_token is set then).
static inline bool read_ply_value(ply_cursor& cursor, ply_type type, double& value) {
  if (cursor.format != ply_format::ascii) {
    auto size = ply_type_size(type);
    if (cursor.size - cursor.pos < size) return false;
    value = load_binary_value(cursor.data + cursor.pos, type, swap_bytes(cursor.format));
    cursor.pos += size;
    return true;
  }
  while (cursor.pos < cursor.size && std::isspace((unsigned char)cursor.data[cursor.pos])) {
    if (cursor.data[cursor.pos] == '\n') cursor.line++;
    cursor.pos++;
  }
  if (cursor.pos == cursor.size) return false;
  auto start = cursor.pos;
  while (cursor.pos < cursor.size && !std::isspace((unsigned char)cursor.data[cursor.pos]))
    cursor.pos++;
  auto first = cursor.data + start, last = cursor.data + cursor.pos;
  if (*first == '+') first++;  // from_chars does not take a leading plus
  auto result = std::from_chars(first, last, value);
  if (result.ec != std::errc{} || result.ptr != last) {
    cursor.bad_token = true;
    cursor.token     = std::string(cursor.data + start, cursor.data + cursor.pos);
    return false;
  }
  return true;
}

static bool ply_data_error(const std::string& filename, const ply_cursor& cursor,
    const ply_element& element, size_t row, std::string& error) {
  if (cursor.bad_token) {
    error = filename + ": line " + std::to_string(cursor.line) + ": element " +
            element.name + " index " + std::to_string(row) + ": \"" + cursor.token +
            "\" is not a number";
  } else {
    error = filename + ": element " + element.name + " ran out of data at index " +
            std::to_string(row) + " of " + std::to_string(element.count);
  }
  return false;
}

static bool parse_ply_header(const std::string& filename, ply_cursor& cursor,
    std::vector<ply_element>& elements, std::string& error) {
  auto has_format = false;
  auto line_error = [&](const std::string& message) {
    error = filename + ": line " + std::to_string(cursor.line) + ": " + message;
    return false;
  };
  while (true) {
    if (cursor.pos >= cursor.size)
      return line_error("header ends without end_header");
    auto end = std::find(cursor.data + cursor.pos, cursor.data + cursor.size, '\n');
    auto text = std::string(cursor.data + cursor.pos, end);
    cursor.pos = end - cursor.data + (end != cursor.data + cursor.size ? 1 : 0);
    if (!text.empty() && text.back() == '\r') text.pop_back();
    auto tokens = std::vector<std::string>{};
    for (size_t i = 0; i < text.size();) {
      while (i < text.size() && std::isspace((unsigned char)text[i])) i++;
      auto start = i;
      while (i < text.size() && !std::isspace((unsigned char)text[i])) i++;
      if (i > start) tokens.push_back(text.substr(start, i - start));
    }
    if (cursor.line == 1) {
      if (tokens.size() != 1 || tokens[0] != "ply")
        return line_error("not a PLY file (expected \"ply\")");
    } else if (tokens.empty() || tokens[0] == "comment" || tokens[0] == "obj_info") {
      // nothing to read
    } else if (tokens[0] == "format") {
      if (tokens.size() != 3) return line_error("expected \"format TYPE 1.0\"");
      if (tokens[1] == "ascii") cursor.format = ply_format::ascii;
      else if (tokens[1] == "binary_little_endian")
        cursor.format = ply_format::binary_little_endian;
      else if (tokens[1] == "binary_big_endian")
        cursor.format = ply_format::binary_big_endian;
      else return line_error("unknown format \"" + tokens[1] + "\"");
      has_format = true;
    } else if (tokens[0] == "element") {
      if (tokens.size() != 3) return line_error("expected \"element NAME COUNT\"");
      auto count  = (unsigned long long)0;
      auto& value = tokens[2];
      auto  result = std::from_chars(value.data(), value.data() + value.size(), count);
      if (result.ec != std::errc{} || result.ptr != value.data() + value.size())
        return line_error("bad count \"" + value + "\" for element " + tokens[1]);
      elements.push_back({tokens[1], (size_t)count, {}});
    } else if (tokens[0] == "property") {
      if (elements.empty()) return line_error("property before any element");
      auto property = ply_property{};
      if (tokens.size() == 5 && tokens[1] == "list") {
        if (!parse_ply_type(tokens[2], property.count_type))
          return line_error("unknown property type \"" + tokens[2] + "\"");
        if (!parse_ply_type(tokens[3], property.type))
          return line_error("unknown property type \"" + tokens[3] + "\"");
        property.is_list = true;
        property.name    = tokens[4];
      } else if (tokens.size() == 3 && tokens[1] != "list") {
        if (!parse_ply_type(tokens[1], property.type))
          return line_error("unknown property type \"" + tokens[1] + "\"");
        property.name = tokens[2];
      } else {
        return line_error("expected \"property TYPE NAME\" or "
                          "\"property list COUNT_TYPE TYPE NAME\"");
      }
      elements.back().properties.push_back(property);
    } else if (tokens[0] == "end_header") {
      if (!has_format) return line_error("end_header before any format line");
      cursor.line++;
      return true;
    } else {
      return line_error("unknown header keyword \"" + tokens[0] + "\"");
    }
    cursor.line++;
  }
}

// Vertex properties we keep, each read into its own column.
enum struct ply_column { x, y, z, nx, ny, nz, u, v, radius, red, green, blue };

static int ply_vertex_column(const std::string& name) {
  static const auto names = std::unordered_map<std::string, ply_column>{
      {"x", ply_column::x}, {"y", ply_column::y}, {"z", ply_column::z},
      {"nx", ply_column::nx}, {"ny", ply_column::ny}, {"nz", ply_column::nz},
      {"u", ply_column::u}, {"s", ply_column::u}, {"texture_u", ply_column::u},
      {"texture_s", ply_column::u}, {"v", ply_column::v}, {"t", ply_column::v},
      {"texture_v", ply_column::v}, {"texture_t", ply_column::v},
      {"radius", ply_column::radius}, {"red", ply_column::red},
      {"green", ply_column::green}, {"blue", ply_column::blue}};
  auto found = names.find(name);
  return found == names.end() ? -1 : (int)found->second;
}

// Fewest bytes one row of the element can take: bounds memory reserved
// from a header count that the data may not back.
static size_t ply_min_row_bytes(const ply_element& element, ply_format format) {
  auto bytes = (size_t)0;
  for (auto& property : element.properties) {
    if (format == ply_format::ascii) bytes += 2;
    else bytes += ply_type_size(property.is_list ? property.count_type : property.type);
  }
  return std::max(bytes, (size_t)1);
}

// Reads the rows of one element: scalar property p of row r goes to
// on_scalar(p, r, value), list property p to on_list(p, r, values), which
// returns false (with the error set) to stop.
template <typename OnScalar, typename OnList>
static bool read_ply_rows(const std::string& filename, ply_cursor& cursor,
    const ply_element& element, OnScalar&& on_scalar, OnList&& on_list,
    std::string& error) {
  // Rows without properties take no bytes, however many the header claims.
  if (element.properties.empty()) return true;
  auto has_lists = false;
  for (auto& property : element.properties) has_lists |= property.is_list;
  if (cursor.format != ply_format::ascii && !has_lists) {
    // Fixed-size rows: check the size once, then read column by column.
    auto stride = (size_t)0;
    for (auto& property : element.properties) stride += ply_type_size(property.type);
    if (stride == 0) return true;
    auto available = (cursor.size - cursor.pos) / stride;
    if (available < element.count)
      return ply_data_error(filename, cursor, element, available, error);
    auto swap   = swap_bytes(cursor.format);
    auto offset = (size_t)0;
    for (auto p = 0; p < (int)element.properties.size(); p++) {
      auto  type   = element.properties[p].type;
      auto* base   = cursor.data + cursor.pos + offset;
      auto  column = [&](auto typed) {
        using T = decltype(typed);
        for (size_t row = 0; row < element.count; row++)
          on_scalar(p, row, (double)load_raw<T>(base + row * stride, swap));
      };
      switch (type) {  // outside the loop over rows
        case ply_type::i8: column(int8_t{}); break;
        case ply_type::u8: column(uint8_t{}); break;
        case ply_type::i16: column(int16_t{}); break;
        case ply_type::u16: column(uint16_t{}); break;
        case ply_type::i32: column(int32_t{}); break;
        case ply_type::u32: column(uint32_t{}); break;
        case ply_type::f32: column(float{}); break;
        case ply_type::f64: column(double{}); break;
      }
      offset += ply_type_size(type);
    }
    cursor.pos += element.count * stride;
    return true;
  }
  auto values = std::vector<double>{};
  for (size_t row = 0; row < element.count; row++) {
    for (auto p = 0; p < (int)element.properties.size(); p++) {
      auto& property = element.properties[p];
      auto  value    = 0.0;
      if (!property.is_list) {
        if (!read_ply_value(cursor, property.type, value))
          return ply_data_error(filename, cursor, element, row, error);
        on_scalar(p, row, value);
        continue;
      }
      if (!read_ply_value(cursor, property.count_type, value))
        return ply_data_error(filename, cursor, element, row, error);
      // A list cannot be longer than the data left: reject absurd lengths
      // before allocating for them.
      if (value < 0 || value != std::floor(value)) {
        error = filename + ": element " + element.name + " index " + std::to_string(row) +
                ": bad list length " + format_float((float)value);
        return false;
      }
      auto min_bytes = cursor.format == ply_format::ascii ? 1 : ply_type_size(property.type);
      if (value * min_bytes > (double)(cursor.size - cursor.pos))
        return ply_data_error(filename, cursor, element, row, error);
      values.resize((size_t)value);
      if (cursor.format != ply_format::ascii) {
        // The length check above covers the whole binary list.
        auto size = ply_type_size(property.type);
        auto swap = swap_bytes(cursor.format);
        for (size_t k = 0; k < values.size(); k++)
          values[k] = load_binary_value(cursor.data + cursor.pos + k * size, property.type, swap);
        cursor.pos += values.size() * size;
      } else {
        for (auto& item : values) {
          if (!read_ply_value(cursor, property.type, item))
            return ply_data_error(filename, cursor, element, row, error);
        }
      }
      if (!on_list(p, row, values)) return false;
    }
  }
  return true;
}

static bool load_ply_shape(
    const std::string& filename, shape_data& shape, std::string& error, double max_memory) {
  auto data = std::string{};
  if (!load_text(filename, data, error, max_memory)) return false;
  auto cursor   = ply_cursor{data.data(), data.size()};
  auto elements = std::vector<ply_element>{};
  if (!parse_ply_header(filename, cursor, elements, error)) return false;

  // The vertex count is known from the header, so indices can be checked as
  // they are read, whatever the element order.
  auto num_vertices = (size_t)0, num_vertex_elements = (size_t)0;
  for (auto& element : elements) {
    if (element.name != "vertex") continue;
    num_vertices = element.count;
    num_vertex_elements++;
  }
  if (num_vertex_elements > 1) {
    error = filename + ": more than one vertex element";
    return false;
  }

  auto kinds = 0;
  for (auto& element : elements) {
    auto remaining = data.size() - cursor.pos;
    auto max_rows  = std::min(element.count,
         remaining / ply_min_row_bytes(element, cursor.format) + 1);
    if (element.name == "vertex") {
      auto columns = std::vector<int>{};
      for (auto& property : element.properties)
        columns.push_back(property.is_list ? -1 : ply_vertex_column(property.name));
      auto has = [&](ply_column c) {
        return std::find(columns.begin(), columns.end(), (int)c) != columns.end();
      };
      for (auto c : {ply_column::x, ply_column::y, ply_column::z}) {
        if (!has(c)) {
          error = filename + ": element vertex has no property " +
                  std::string(1, "xyz"[(int)c]);
          return false;
        }
      }
      // A normal or texcoord group is all there or not at all: half a
      // normal has no meaning.
      for (auto group : {std::vector{ply_column::nx, ply_column::ny, ply_column::nz},
               std::vector{ply_column::u, ply_column::v},
               std::vector{ply_column::red, ply_column::green, ply_column::blue}}) {
        auto present = 0;
        for (auto c : group) present += has(c) ? 1 : 0;
        if (present == 0 || present == (int)group.size()) continue;
        for (auto p = 0; p < (int)columns.size(); p++) {
          if (std::find(group.begin(), group.end(), (ply_column)columns[p]) == group.end())
            continue;
          auto colors = group[0] == ply_column::red;
          error = filename + ": element vertex property " + element.properties[p].name +
                  ": incomplete " +
                  (colors ? "color" : group.size() == 3 ? "normal" : "texcoord") + " (" +
                  (colors ? "red green blue" : group.size() == 3 ? "nx ny nz" : "u v") +
                  " needed)";
          return false;
        }
      }
      // Each property is written straight to its place in the shape: no
      // intermediate columns for millions of vertices.
      static_assert(sizeof(vec3f) == 3 * sizeof(float) && sizeof(vec2f) == 2 * sizeof(float));
      shape.positions.resize(max_rows);
      if (has(ply_column::nx)) shape.normals.resize(max_rows);
      if (has(ply_column::u)) shape.texcoords.resize(max_rows);
      if (has(ply_column::radius)) shape.radius.resize(max_rows);
      if (has(ply_column::red)) shape.colors.resize(max_rows);
      auto targets = std::vector<float*>(columns.size(), nullptr);
      auto strides = std::vector<size_t>(columns.size(), 0);
      // Colours stored as integers are in [0, 255] (the PLY habit), floats in [0, 1].
      auto scales  = std::vector<double>(columns.size(), 1.0);
      auto in      = [](int c, ply_column first, ply_column last) {
        return c >= (int)first && c <= (int)last;
      };
      // Without rows the columns have no storage (data() may be null, and
      // null plus an offset is undefined): no targets, nothing to write.
      for (size_t p = 0; p < columns.size() && max_rows > 0; p++) {
        auto c = columns[p];
        if (in(c, ply_column::x, ply_column::z)) {
          targets[p] = (float*)shape.positions.data() + c, strides[p] = 3;
        } else if (in(c, ply_column::nx, ply_column::nz)) {
          targets[p] = (float*)shape.normals.data() + (c - (int)ply_column::nx), strides[p] = 3;
        } else if (in(c, ply_column::u, ply_column::v)) {
          targets[p] = (float*)shape.texcoords.data() + (c - (int)ply_column::u), strides[p] = 2;
        } else if (c == (int)ply_column::radius) {
          targets[p] = shape.radius.data(), strides[p] = 1;
        } else if (in(c, ply_column::red, ply_column::blue)) {
          targets[p] = (float*)shape.colors.data() + (c - (int)ply_column::red), strides[p] = 3;
          auto type  = element.properties[p].type;
          if (type == ply_type::u8) scales[p] = 1.0 / 255;
          if (type == ply_type::u16) scales[p] = 1.0 / 65535;
        }
      }
      auto on_scalar = [&](int p, size_t row, double value) {
        if (targets[p] && row < max_rows)
          targets[p][row * strides[p]] = (float)(value * scales[p]);
      };
      auto on_list = [](int, size_t, const std::vector<double>&) { return true; };
      if (!read_ply_rows(filename, cursor, element, on_scalar, on_list, error)) return false;
      continue;
    }
    auto is_face = element.name == "face", is_line = element.name == "line",
         is_curve = element.name == "curve";
    auto index_property = -1;
    for (auto p = 0; p < (int)element.properties.size(); p++) {
      auto& property = element.properties[p];
      if (property.is_list &&
          (property.name == "vertex_indices" || property.name == "vertex_index"))
        index_property = p;
    }
    if ((is_face || is_line || is_curve) && index_property < 0) {
      error = filename + ": element " + element.name + " has no vertex_indices list";
      return false;
    }
    if ((is_face || is_line || is_curve) && element.count > 0) kinds++;
    if (is_face) shape.triangles.reserve(max_rows);
    if (is_line) shape.lines.reserve(max_rows);
    if (is_curve) shape.curves.reserve(max_rows);
    auto on_scalar = [](int, size_t, double) {};
    auto on_list   = [&](int p, size_t row, const std::vector<double>& values) {
      if (p != index_property || !(is_face || is_line || is_curve)) return true;
      auto row_error = [&](const std::string& message) {
        error = filename + ": element " + element.name + " index " + std::to_string(row) +
                ": " + message;
        return false;
      };
      for (auto value : values) {
        if (value < 0 || value >= (double)num_vertices || value != std::floor(value))
          return row_error("vertex index " + format_float((float)value) +
                           " out of range (" + std::to_string(num_vertices) +
                           " vertices)");
      }
      auto count = values.size();
      if (is_face) {
        if (count < 3)
          return row_error("has " + std::to_string(count) + " vertices, at least 3 needed");
        // Polygons become a triangle fan around their first vertex.
        for (size_t k = 1; k + 1 < count; k++)
          shape.triangles.push_back({(int)values[0], (int)values[k], (int)values[k + 1]});
      } else if (is_line) {
        if (count < 2)
          return row_error("has " + std::to_string(count) + " vertices, at least 2 needed");
        // Polylines become consecutive segments.
        for (size_t k = 0; k + 1 < count; k++)
          shape.lines.push_back({(int)values[k], (int)values[k + 1]});
      } else {
        if (count != 4)
          return row_error("has " + std::to_string(count) + " vertices, expected 4");
        shape.curves.push_back(
            {(int)values[0], (int)values[1], (int)values[2], (int)values[3]});
      }
      return true;
    };
    if (!read_ply_rows(filename, cursor, element, on_scalar, on_list, error)) return false;
  }
  if (kinds > 1) {
    error = filename + ": holds more than one of faces, lines and curves";
    return false;
  }

  // No NaN or Inf may reach the renderer.
  auto check_finite = [&](const float* values, size_t count, size_t stride) {
    for (size_t i = 0; i < count * stride; i++) {
      if (!std::isfinite(values[i])) {
        error = filename + ": element vertex index " + std::to_string(i / stride) +
                ": value is not finite";
        return false;
      }
    }
    return true;
  };
  if (!check_finite((const float*)shape.positions.data(), shape.positions.size(), 3) ||
      !check_finite((const float*)shape.normals.data(), shape.normals.size(), 3) ||
      !check_finite((const float*)shape.texcoords.data(), shape.texcoords.size(), 2) ||
      !check_finite((const float*)shape.colors.data(), shape.colors.size(), 3))
    return false;
  for (size_t i = 0; i < shape.radius.size(); i++) {
    if (!std::isfinite(shape.radius[i]) || shape.radius[i] < 0) {
      error = filename + ": element vertex index " + std::to_string(i) +
              ": radius is negative or not finite";
      return false;
    }
  }
  return true;
}

bool load_shape(
    const std::string& filename, shape_data& shape, std::string& error, double max_memory) try {
  shape = {};
  if (load_ply_shape(filename, shape, error, max_memory)) return true;
  shape = {};  // nothing half-read escapes
  return false;
} catch (const std::bad_alloc&) {
  // Past the budget's checks, the system (or ulimit -v) gave less.
  shape = {};
  error = allocation_error(filename, "its elements");
  return false;
}

bool encode_shape(const std::string& filename, const shape_data& shape,
    std::string& data, std::string& error, bool ascii) {
  // A shape packed for rendering (pack_fiber_vertices) is saved as loaded.
  if (!shape.fiber_vertices.empty()) {
    auto plain = shape;
    unpack_fiber_vertices(plain);
    return encode_shape(filename, plain, data, error, ascii);
  }
  auto num_vertices = shape.positions.size();
  auto check_size   = [&](size_t size, const char* what) {
    if (size == 0 || size == num_vertices) return true;
    error = filename + ": cannot save shape: " + what + " has " + std::to_string(size) +
            " values for " + std::to_string(num_vertices) + " vertices";
    return false;
  };
  if (!check_size(shape.normals.size(), "normals") ||
      !check_size(shape.texcoords.size(), "texcoords") ||
      !check_size(shape.radius.size(), "radius") ||
      !check_size(shape.colors.size(), "colors"))
    return false;
  auto kinds = (int)!shape.triangles.empty() + (int)!shape.lines.empty() +
               (int)!shape.curves.empty();
  if (kinds > 1) {
    error = filename + ": cannot save shape: it holds more than one of triangles, "
                       "lines and curves";
    return false;
  }

  // Element: name, number of indices per element, the indices.
  auto element_name = std::string{};
  auto element_size = 0;
  auto indices      = (const int*)nullptr;
  auto num_elements = (size_t)0;
  if (!shape.triangles.empty()) {
    element_name = "face", element_size = 3, num_elements = shape.triangles.size();
    indices = &shape.triangles[0].x;
  } else if (!shape.lines.empty()) {
    element_name = "line", element_size = 2, num_elements = shape.lines.size();
    indices = &shape.lines[0].x;
  } else if (!shape.curves.empty()) {
    element_name = "curve", element_size = 4, num_elements = shape.curves.size();
    indices = &shape.curves[0].x;
  }

  data = "ply\nformat ";
  data += ascii ? "ascii" : "binary_little_endian";
  data += " 1.0\ncomment Written by yocto-hair\n";
  data += "element vertex " + std::to_string(num_vertices) + "\n";
  data += "property float x\nproperty float y\nproperty float z\n";
  if (!shape.normals.empty()) data += "property float nx\nproperty float ny\nproperty float nz\n";
  if (!shape.texcoords.empty()) data += "property float u\nproperty float v\n";
  if (!shape.radius.empty()) data += "property float radius\n";
  if (!shape.colors.empty()) data += "property float red\nproperty float green\nproperty float blue\n";
  if (num_elements > 0) {
    data += "element " + element_name + " " + std::to_string(num_elements) + "\n";
    data += "property list uchar int vertex_indices\n";
  }
  data += "end_header\n";

  // One row of vertex values, in header order.
  auto row    = std::vector<float>{};
  auto values = [&](size_t i) {
    row.clear();
    row.insert(row.end(), {shape.positions[i].x, shape.positions[i].y, shape.positions[i].z});
    if (!shape.normals.empty())
      row.insert(row.end(), {shape.normals[i].x, shape.normals[i].y, shape.normals[i].z});
    if (!shape.texcoords.empty())
      row.insert(row.end(), {shape.texcoords[i].x, shape.texcoords[i].y});
    if (!shape.radius.empty()) row.push_back(shape.radius[i]);
    if (!shape.colors.empty())
      row.insert(row.end(), {shape.colors[i].x, shape.colors[i].y, shape.colors[i].z});
  };
  if (ascii) {
    for (size_t i = 0; i < num_vertices; i++) {
      values(i);
      for (size_t k = 0; k < row.size(); k++) {
        if (k > 0) data += ' ';
        data += format_float(row[k]);
      }
      data += '\n';
    }
    for (size_t e = 0; e < num_elements; e++) {
      data += std::to_string(element_size);
      for (auto k = 0; k < element_size; k++)
        data += " " + std::to_string(indices[e * element_size + k]);
      data += '\n';
    }
  } else {
    auto row_size = 3 + (shape.normals.empty() ? 0 : 3) +
                    (shape.texcoords.empty() ? 0 : 2) + (shape.radius.empty() ? 0 : 1) +
                    (shape.colors.empty() ? 0 : 3);
    data.reserve(data.size() + num_vertices * row_size * 4 +
                 num_elements * (1 + 4 * element_size));
    for (size_t i = 0; i < num_vertices; i++) {
      values(i);
      for (auto value : row) append_raw(data, value);
    }
    for (size_t e = 0; e < num_elements; e++) {
      append_raw(data, (uint8_t)element_size);
      for (auto k = 0; k < element_size; k++)
        append_raw(data, (int32_t)indices[e * element_size + k]);
    }
  }
  return true;
}

bool save_shape(const std::string& filename, const shape_data& shape,
    std::string& error, bool ascii) {
  auto data = std::string{};
  if (!encode_shape(filename, shape, data, error, ascii)) return false;
  return save_text(filename, data, error);
}

}  // namespace yocto
