//
// Implementation of Yocto/SceneIO: see yocto_sceneio.h.
//

#include "yocto_sceneio.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/random.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string_view>
#include <unordered_map>
#include <unordered_set>

// -----------------------------------------------------------------------------
// FILE HELPERS
// -----------------------------------------------------------------------------
namespace yocto {

std::string path_dirname(const std::string& filename) {
  auto slash = filename.find_last_of("/\\");
  return slash == std::string::npos ? std::string{} : filename.substr(0, slash + 1);
}

std::string path_extension(const std::string& filename) {
  auto slash = filename.find_last_of("/\\");
  auto dot   = filename.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash))
    return "";
  auto extension = filename.substr(dot);
  for (auto& c : extension) c = (char)std::tolower((unsigned char)c);
  return extension;
}

std::string path_join(const std::string& directory, const std::string& filename) {
  if (directory.empty() || (!filename.empty() && filename.front() == '/')) return filename;
  if (filename.empty()) return directory;
  if (directory.back() == '/' || directory.back() == '\\') return directory + filename;
  return directory + "/" + filename;
}

// Paths to remove when a command fails or is killed: temporaries being
// written and folders made for outputs. Fixed slots of heap strings, so that
// a signal handler can walk them without locks or allocation.
struct pending_path {
  std::atomic<char*> path      = nullptr;
  std::atomic<bool>  directory = false;
};
static pending_path pending_paths[4096];

static void add_pending_path(const std::string& path, bool directory) {
  for (auto& slot : pending_paths) {
    if (slot.path.load() != nullptr) continue;
    auto copy     = strdup(path.c_str());
    auto expected = (char*)nullptr;
    slot.directory = directory;
    if (slot.path.compare_exchange_strong(expected, copy)) return;
    std::free(copy);
  }
  // All slots taken: the path is still cleaned up on the normal exit paths.
}

static void remove_pending_path(const std::string& path) {
  for (auto& slot : pending_paths) {
    auto current = slot.path.load();
    if (current == nullptr || path != current) continue;
    if (slot.path.compare_exchange_strong(current, nullptr)) std::free(current);
    return;
  }
}

void remove_pending_outputs() {
  // Files first, then folders deepest first (they were listed top down).
  for (auto& slot : pending_paths) {
    auto path = slot.path.load();
    if (path != nullptr && !slot.directory) unlink(path);
  }
  for (auto i = (int)std::size(pending_paths) - 1; i >= 0; i--) {
    auto path = pending_paths[i].path.load();
    if (path != nullptr && pending_paths[i].directory) rmdir(path);
  }
}

// Unpredictable temporary names: another local user cannot guess one and
// plant a link there, and O_EXCL refuses anything already there anyway.
static std::string random_suffix() {
  uint8_t bytes[8] = {};
  if (getrandom(bytes, sizeof(bytes), 0) != (ssize_t)sizeof(bytes)) {
    static auto counter = std::atomic<uint64_t>{0};
    auto        value   = (uint64_t)getpid() * 0x9e3779b97f4a7c15ull ^
                 (uint64_t)std::chrono::steady_clock::now().time_since_epoch().count() ^
                 (counter++ << 48);
    std::memcpy(bytes, &value, sizeof(bytes));
  }
  static const char digits[] = "abcdefghijklmnopqrstuvwxyz012345";
  auto suffix = std::string{};
  for (auto byte : bytes) suffix += digits[byte & 31];
  return suffix;
}

// NAME.tmp-RANDOM.EXT next to filename: the extension stays last, since
// image writers pick the format from it.
static std::string temporary_name(const std::string& filename) {
  auto directory = path_dirname(filename);
  auto base      = filename.substr(directory.size());
  auto dot       = base.find_last_of('.');
  auto stem      = dot == std::string::npos || dot == 0 ? base : base.substr(0, dot);
  auto extension = stem.size() == base.size() ? std::string{} : base.substr(dot);
  return directory + stem + ".tmp-" + random_suffix() + extension;
}

bool open_output_file(output_file& file, const std::string& filename, std::string& error) {
  file = {};
  for (auto attempt = 0; attempt < 16; attempt++) {
    auto temporary = temporary_name(filename);
    // Listed before it exists, so no signal can leave it behind.
    add_pending_path(temporary, false);
    auto descriptor = open(temporary.c_str(),
        O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0666);
    if (descriptor >= 0) {
      file = {filename, temporary, descriptor, 0};
      return true;
    }
    auto code = errno;
    remove_pending_path(temporary);
    if (code != EEXIST) {
      error = filename + ": cannot create file (" + std::strerror(code) + ")";
      return false;
    }
  }
  error = filename + ": cannot create a temporary file next to it";
  return false;
}

bool write_output_file(output_file& file, const void* data, size_t size, std::string& error) {
  auto bytes = (const char*)data;
  while (size > 0) {
    auto count = write(file.descriptor, bytes, std::min(size, (size_t)1 << 30));
    if (count < 0 && errno == EINTR) continue;
    if (count <= 0) {
      error = file.filename + ": cannot write file (" +
              (count < 0 ? std::strerror(errno) : "no progress") + ")";
      return false;
    }
    bytes += count;
    size -= (size_t)count;
    file.written += (size_t)count;
  }
  return true;
}

bool finish_output_file(output_file& file, std::string& error) {
  if (file.descriptor < 0) return true;
  // Delayed allocation reports a full disk at fsync or close, not at write.
  auto status = (struct stat){};
  auto code   = 0;
  if (fsync(file.descriptor) != 0) code = errno;
  else if (fstat(file.descriptor, &status) != 0) code = errno;
  if (close(file.descriptor) != 0 && code == 0) code = errno;
  file.descriptor = -1;
  if (code != 0) {
    error = file.filename + ": cannot write file (" + std::strerror(code) + ")";
    return false;
  }
  if ((size_t)status.st_size != file.written) {
    error = file.filename + ": cannot write file (" + std::to_string(status.st_size) +
            " of " + std::to_string(file.written) + " bytes on disk)";
    return false;
  }
  return true;
}

void discard_output_file(output_file& file) {
  if (file.descriptor >= 0) close(file.descriptor);
  if (!file.temporary.empty()) {
    unlink(file.temporary.c_str());
    remove_pending_path(file.temporary);
  }
  file = {};
}

void discard_output_files(std::vector<output_file>& files) {
  for (auto& file : files) discard_output_file(file);
}

// Blocks the signals that end a command while a commit renames its files.
struct signal_blocker {
  sigset_t previous = {};
  signal_blocker() {
    auto blocked = sigset_t{};
    sigemptyset(&blocked);
    for (auto signal : {SIGINT, SIGTERM, SIGHUP, SIGQUIT}) sigaddset(&blocked, signal);
    pthread_sigmask(SIG_BLOCK, &blocked, &previous);
  }
  ~signal_blocker() { pthread_sigmask(SIG_SETMASK, &previous, nullptr); }
};

bool commit_output_files(std::vector<output_file>& files, std::string& error, bool replace) {
  for (auto& file : files) {
    if (!finish_output_file(file, error)) return discard_output_files(files), false;
  }
  auto blocker = signal_blocker{};
  // Backups (hard links) of the files a multi-file commit replaces, so that
  // a failed rename can put every one back; one file needs none, its rename
  // is atomic.
  auto backups = std::vector<std::string>(files.size());
  auto created = std::vector<bool>(files.size(), false);
  auto undo    = [&](size_t count, const std::string& message) {
    for (size_t i = 0; i < count; i++) {
      if (!backups[i].empty()) rename(backups[i].c_str(), files[i].filename.c_str());
      else if (created[i]) unlink(files[i].filename.c_str());
    }
    for (auto& backup : backups)
      if (!backup.empty()) unlink(backup.c_str());
    discard_output_files(files);
    error = message;
    return false;
  };
  for (size_t i = 0; i < files.size(); i++) {
    auto& file   = files[i];
    auto  status = (struct stat){};
    auto  exists = lstat(file.filename.c_str(), &status) == 0;
    if (exists && S_ISDIR(status.st_mode))
      return undo(i, file.filename + ": is a directory, not a file");
    if (!replace) {
      // link fails if the name exists: nothing is ever overwritten.
      if (link(file.temporary.c_str(), file.filename.c_str()) != 0)
        return undo(i, file.filename + ": cannot create file (" + std::strerror(errno) + ")");
      created[i] = true;
      unlink(file.temporary.c_str());
      continue;
    }
    if (exists && files.size() > 1) {
      auto backup = temporary_name(file.filename);
      if (link(file.filename.c_str(), backup.c_str()) == 0) backups[i] = backup;
    }
    if (rename(file.temporary.c_str(), file.filename.c_str()) != 0)
      return undo(i, file.filename + ": cannot rename temporary file (" +
                         std::strerror(errno) + ")");
    created[i] = !exists;
  }
  for (auto& backup : backups)
    if (!backup.empty()) unlink(backup.c_str());
  for (auto& file : files) remove_pending_path(file.temporary), file = {};
  return true;
}

bool commit_output_file(output_file& file, std::string& error, bool replace) {
  auto files = std::vector<output_file>{file};
  auto ok    = commit_output_files(files, error, replace);
  file       = {};
  return ok;
}

bool check_output_file(const std::string& filename, double bytes, std::string& error) {
  auto status = (struct stat){};
  if (stat(filename.c_str(), &status) == 0 && S_ISDIR(status.st_mode)) {
    error = filename + ": is a directory, not a file";
    return false;
  }
  // A real file in the folder proves it takes one (permissions, read-only
  // or full file systems, a missing folder).
  auto file = output_file{};
  if (!open_output_file(file, filename, error)) return false;
  discard_output_file(file);
  auto directory = path_dirname(filename);
  auto space     = (struct statvfs){};
  if (statvfs(directory.empty() ? "." : directory.c_str(), &space) == 0) {
    auto available = (double)space.f_bavail * (double)space.f_frsize;
    if (available < bytes) {
      error = filename + ": not enough free space (" +
              std::to_string((long long)std::ceil(bytes / (1 << 20))) + " MiB needed, " +
              std::to_string((long long)(available / (1 << 20))) + " MiB free)";
      return false;
    }
  }
  return true;
}

static std::vector<std::string> created_directories;

bool make_output_directories(const std::string& directory, std::string& error) {
  if (directory.empty()) return true;
  // Each missing component from the top down, listed as it is made.
  auto path = std::filesystem::path(directory).lexically_normal();
  auto current = std::filesystem::path{};
  for (auto& part : path) {
    current /= part;
    if (part.empty() || part == "/" || part == "." || part == "..") continue;
    auto name   = current.string();
    auto status = (struct stat){};
    if (stat(name.c_str(), &status) == 0) {
      if (S_ISDIR(status.st_mode)) continue;
      error = name + ": cannot create directory (a file is in the way)";
      return false;
    }
    add_pending_path(name, true);
    if (mkdir(name.c_str(), 0777) != 0 && errno != EEXIST) {
      error = name + ": cannot create directory (" + std::strerror(errno) + ")";
      remove_pending_path(name);
      return false;
    }
    created_directories.push_back(name);
  }
  return true;
}

void keep_output_directories() {
  for (auto& directory : created_directories) remove_pending_path(directory);
  created_directories.clear();
}

void remove_output_directories() {
  // Only empty ones: rmdir refuses the rest.
  for (auto it = created_directories.rbegin(); it != created_directories.rend(); ++it) {
    rmdir(it->c_str());
    remove_pending_path(*it);
  }
  created_directories.clear();
}

static double default_load_memory_limit() {
  auto pages = sysconf(_SC_PHYS_PAGES), page_size = sysconf(_SC_PAGE_SIZE);
  auto limit = pages > 0 && page_size > 0 ? (double)pages * (double)page_size
                                          : 8.0 * (1 << 30);
  auto address_space = rlimit{};
  if (getrlimit(RLIMIT_AS, &address_space) == 0 &&
      address_space.rlim_cur != RLIM_INFINITY)
    limit = std::min(limit, (double)address_space.rlim_cur);
  return 0.75 * limit;
}

double load_memory_limit = default_load_memory_limit();

bool check_load_memory(const std::string& filename, const std::string& what,
    double bytes, std::string& error) {
  if (bytes <= load_memory_limit) return true;
  auto mebibytes = [](double bytes) {
    return std::to_string((long long)std::ceil(bytes / (1 << 20)));
  };
  error = filename + ": " + what + " needs " + mebibytes(bytes) +
          " MiB, over the memory limit of " + mebibytes(load_memory_limit) +
          " MiB (--max-memory)";
  return false;
}

// The message for a file that is not a regular one; the size if it is.
static bool check_file_type(const std::string& filename, const struct stat& info,
    size_t& size, std::string& error) {
  if (S_ISREG(info.st_mode)) {
    size = (size_t)info.st_size;
    return true;
  }
  if (S_ISDIR(info.st_mode)) error = filename + ": is a directory, not a file";
  else error = filename + ": is a device, fifo or socket, not a regular file";
  return false;
}

bool check_input_file(const std::string& filename, size_t& size, std::string& error) {
  auto info = (struct stat){};
  if (::stat(filename.c_str(), &info) != 0) {
    error = filename + ": cannot open file (" + std::strerror(errno) + ")";
    return false;
  }
  return check_file_type(filename, info, size, error);
}

// Reads a whole file in one go: PLY files with millions of curves are parsed
// from memory, never value by value through a stream. The file is opened
// without blocking (a fifo would wait for a writer) and checked once open,
// so that what is read is what was checked.
static bool load_binary(const std::string& filename, std::string& data, std::string& error) {
  data.clear();
  auto fd = ::open(filename.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    error = filename + ": cannot open file (" + std::strerror(errno) + ")";
    return false;
  }
  auto fail = [&]() {
    ::close(fd);
    data.clear();
    return false;
  };
  auto read_error = [&]() {
    error = filename + ": cannot read file (" + std::strerror(errno) + ")";
    return fail();
  };
  auto info = (struct stat){};
  auto size = (size_t)0;
  if (::fstat(fd, &info) != 0) return read_error();
  if (!check_file_type(filename, info, size, error) ||
      !check_load_memory(filename, "reading the file", (double)size, error))
    return fail();
  auto read_some = [&](char* buffer, size_t count) {
    auto result = ::read(fd, buffer, count);
    while (result < 0 && errno == EINTR) result = ::read(fd, buffer, count);
    return result;
  };
  // The size first, then on in chunks for files whose size the system does
  // not tell (those in /proc say 0), within the memory limit.
  data.resize(size);
  auto done = (size_t)0;
  while (done < size) {
    auto count = read_some(data.data() + done, size - done);
    if (count < 0) return read_error();
    if (count == 0) break;
    done += (size_t)count;
  }
  data.resize(done);
  char buffer[1 << 16];
  while (true) {
    auto count = read_some(buffer, sizeof(buffer));
    if (count < 0) return read_error();
    if (count == 0) break;
    if (!check_load_memory(filename, "reading the file", (double)(data.size() + count), error))
      return fail();
    data.append(buffer, (size_t)count);
  }
  ::close(fd);
  return true;
}

// Writes data through a temporary next to filename, checked and renamed.
static bool save_binary(const std::string& filename, const std::string& data,
    std::string& error, bool replace = true) {
  auto file = output_file{};
  if (!open_output_file(file, filename, error)) return false;
  if (!write_output_file(file, data.data(), data.size(), error)) {
    discard_output_file(file);
    return false;
  }
  return commit_output_file(file, error, replace);
}

bool load_text(const std::string& filename, std::string& text, std::string& error) {
  return load_binary(filename, text, error);
}

bool save_text(const std::string& filename, const std::string& text, std::string& error) {
  return save_binary(filename, text, error);
}

// Shortest decimal form of a float that reads back to the same float.
static std::string format_float(float value) {
  char buffer[64];
  auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

}  // namespace yocto

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

static constexpr bool host_little_endian = __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__;

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
    const std::string& filename, shape_data& shape, std::string& error) {
  auto data = std::string{};
  if (!load_binary(filename, data, error)) return false;
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

bool load_shape(const std::string& filename, shape_data& shape, std::string& error) {
  shape = {};
  if (load_ply_shape(filename, shape, error)) return true;
  shape = {};  // nothing half-read escapes
  return false;
}

// Appends a little-endian binary value.
template <typename T>
static inline void append_raw(std::string& buffer, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  if (!host_little_endian) std::reverse(bytes, bytes + sizeof(T));
  buffer.append(bytes, sizeof(T));
}

// Encodes a shape as PLY bytes in memory (filename names it in messages).
static bool encode_shape(const std::string& filename, const shape_data& shape,
    std::string& data, std::string& error, bool ascii) {
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
  return save_binary(filename, data, error);
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// IMAGES
// -----------------------------------------------------------------------------
namespace yocto {

// sRGB transfer function (IEC 61966-2-1).
static float srgb_to_linear(float c) {
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}
static float linear_to_srgb(float c) {
  return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1 / 2.4f) - 0.055f;
}

static bool is_linear_extension(const std::string& extension) {
  return extension == ".exr" || extension == ".hdr" || extension == ".pfm";
}
static bool is_8bit_extension(const std::string& extension) {
  return extension == ".png" || extension == ".jpg" || extension == ".jpeg";
}

// OpenImageIO 2.4 reads PFM but cannot write it: the format is a short
// header and raw little-endian floats, rows from the bottom up.
static void encode_pfm(const texture_data& image, std::string& data) {
  data = "PF\n" + std::to_string(image.width) + " " + std::to_string(image.height) +
         "\n-1.0\n";  // a negative scale means little-endian
  data.reserve(data.size() + image.pixels.size() * 12);
  for (auto j = image.height - 1; j >= 0; j--) {
    for (auto i = 0; i < image.width; i++) {
      auto& pixel = image.pixels[(size_t)j * image.width + i];
      for (auto c = 0; c < 3; c++) append_raw(data, pixel[c]);
    }
  }
}

bool is_image_filename(const std::string& filename) {
  auto extension = path_extension(filename);
  return is_linear_extension(extension) || is_8bit_extension(extension);
}

// Refuses an image whose header claims more pixels than the file can hold or
// than the memory limit allows, before a pixel is allocated. Uncompressed
// formats (PFM, PNM) store every value; PNG's deflate stream inflates at
// most 1032 times (a 258-byte match coded in two bits) into rows of at
// least one filter byte and one bit a pixel. Other formats (EXR, JPEG,
// HDR's run lengths) compress too well to bound: the memory limit alone.
static bool check_image_size(const std::string& filename, const OIIO::ImageSpec& spec,
    const std::string& format, size_t file_size, std::string& error) {
  auto width = (double)spec.width, height = (double)spec.height;
  auto channels = (double)spec.nchannels;
  auto size     = std::to_string(spec.width) + "x" + std::to_string(spec.height);
  auto min_bytes = 0.0;
  if (format == "pnm") {
    // PFM is floats; PNM is binary at its bit depth, or ascii with at least
    // one character a value.
    auto bits = (double)spec.get_int_attribute("oiio:BitsPerSample", 8 * (int)spec.format.size());
    if (spec.get_int_attribute("pnm:binary", 1) != 0)
      min_bytes = height * std::ceil(width * channels * bits / 8);
    else min_bytes = height * width * channels;
  } else if (format == "png") {
    min_bytes = height * (1 + std::ceil(width / 8)) / 1032;
  }
  if (min_bytes > (double)file_size) {
    error = filename + ": the header claims " + size + " pixels, more than the file's " +
            std::to_string(file_size) + " bytes can hold";
    return false;
  }
  // What load_image allocates: the decoder's buffer, the float values read
  // and the RGB pixels kept.
  auto pixels = width * height;
  auto bytes  = pixels * channels * (spec.format.size() + sizeof(float)) +
               pixels * sizeof(vec3f);
  auto what = "a " + size + " image with " + std::to_string(spec.nchannels) +
              (spec.nchannels == 1 ? " channel" : " channels");
  return check_load_memory(filename, what, bytes, error);
}

// Four bytes of a chunk type, printable whatever they hold.
static std::string printable_name(const unsigned char* bytes, int count) {
  auto name = std::string{};
  for (auto i = 0; i < count; i++)
    name += std::isalnum(bytes[i]) ? (char)bytes[i] : '?';
  return name;
}

// libpng allocates an ancillary chunk (iCCP, zTXt, ...) at the length its
// header claims before reading it, inside OpenImageIO's open: a few hundred
// bytes claiming 2 GB allocate 2 GB. Walks the chunk headers of a PNG (by
// its signature, whatever the extension) and refuses a length past the end
// of the file (PNG spec, section 5.3), before OpenImageIO sees the file.
static bool check_png_chunks(const std::string& filename, std::string& error) {
  auto file = std::fopen(filename.c_str(), "rb");
  if (!file) return true;  // OpenImageIO reports it
  unsigned char header[8];
  auto is_png = std::fread(header, 1, 8, file) == 8 &&
                std::memcmp(header, "\x89PNG\r\n\x1a\n", 8) == 0;
  auto offset = (uint64_t)8, size = (uint64_t)0;
  if (is_png && std::fseek(file, 0, SEEK_END) == 0) size = (uint64_t)std::ftell(file);
  auto ok = true;
  while (is_png && ok && offset + 8 <= size) {
    unsigned char chunk[8];
    if (std::fseek(file, (long)offset, SEEK_SET) != 0 || std::fread(chunk, 1, 8, file) != 8)
      break;
    auto length = (uint64_t)chunk[0] << 24 | (uint64_t)chunk[1] << 16 |
                  (uint64_t)chunk[2] << 8 | (uint64_t)chunk[3];
    // Length, type, data and CRC.
    if (offset + 12 + length > size) {
      error = filename + ": PNG chunk \"" + printable_name(chunk + 4, 4) + "\" at byte " +
              std::to_string(offset) + " claims " + std::to_string(length) +
              " bytes, more than the file holds";
      ok = false;
    }
    if (std::memcmp(chunk + 4, "IEND", 4) == 0) break;
    offset += 12 + length;
  }
  std::fclose(file);
  return ok;
}

bool load_image(const std::string& filename, texture_data& image, std::string& error) {
  image = {};
  // OpenImageIO opens the file itself: a device or fifo would never end.
  auto file_size = (size_t)0;
  if (!check_input_file(filename, file_size, error)) return false;
  if (!check_png_chunks(filename, error)) return false;
  // Colours as stored: OpenImageIO would otherwise premultiply them by an
  // alpha that we drop.
  auto config = OIIO::ImageSpec{};
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto input = OIIO::ImageInput::open(filename, &config);
  if (!input) {
    auto message = OIIO::geterror();
    error = filename + ": cannot open image" + (message.empty() ? "" : " (" + message + ")");
    return false;
  }
  auto& spec     = input->spec();
  auto  channels = spec.nchannels;
  if (spec.width <= 0 || spec.height <= 0 || channels <= 0) {
    error = filename + ": image has no pixels";
    return false;
  }
  if (spec.depth > 1) {
    error = filename + ": a volume image (depth " + std::to_string(spec.depth) +
            "), not a picture";
    return false;
  }
  if (!check_image_size(filename, spec, input->format_name(), file_size, error)) return false;
  // Environment sampling indexes pixels with int: guard the count.
  auto num_pixels = (size_t)spec.width * (size_t)spec.height;
  if (num_pixels > ((size_t)1 << 31) / (size_t)channels) {
    error = filename + ": image too large (" + std::to_string(spec.width) + "x" +
            std::to_string(spec.height) + ")";
    return false;
  }
  auto buffer = std::vector<float>(num_pixels * channels);
  if (!input->read_image(0, 0, 0, channels, OIIO::TypeDesc::FLOAT, buffer.data())) {
    error = filename + ": cannot read image (" + input->geterror() + ")";
    return false;
  }
  input->close();

  // Float formats are linear; integer formats are sRGB unless they say
  // otherwise.
  auto colorspace = spec.get_string_attribute("oiio:ColorSpace");
  auto linear     = spec.format.is_floating_point() || colorspace == "Linear" ||
                colorspace == "linear";
  image.width  = spec.width;
  image.height = spec.height;
  image.pixels.resize(num_pixels);
  for (size_t i = 0; i < num_pixels; i++) {
    auto* pixel = buffer.data() + i * channels;
    // Grey (with or without alpha) becomes RGB; alpha is dropped.
    auto rgb = channels < 3 ? vec3f{pixel[0], pixel[0], pixel[0]}
                            : vec3f{pixel[0], pixel[1], pixel[2]};
    if (!linear)
      rgb = {srgb_to_linear(rgb.x), srgb_to_linear(rgb.y), srgb_to_linear(rgb.z)};
    if (!isfinite(rgb)) {
      error = filename + ": pixel (" + std::to_string(i % spec.width) + ", " +
              std::to_string(i / spec.width) + ") is not finite";
      image = {};
      return false;
    }
    image.pixels[i] = rgb;
  }
  return true;
}

// Encodes `pixels`, laid out in the spec's channel formats, into `data` with
// OpenImageIO, in memory; `what` names the file in the errors.
static bool encode_with_oiio(const std::string& filename, const std::string& what,
    OIIO::ImageSpec spec, const void* pixels, std::string& data, std::string& error) {
  auto output = OIIO::ImageOutput::create(filename);
  if (!output) {
    error = filename + ": cannot save " + what + " (" + OIIO::geterror() + ")";
    return false;
  }
  auto bytes  = std::vector<unsigned char>{};
  auto memory = OIIO::Filesystem::IOVecOutput(bytes);
  auto proxy  = (OIIO::Filesystem::IOProxy*)&memory;
  spec.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &proxy);
  auto failed = [&](const std::string& step) {
    error = filename + ": cannot " + step + " " + what + " (" + output->geterror() + ")";
    return false;
  };
  if (!output->open(filename, spec)) return failed("create");
  if (!output->write_image(OIIO::TypeDesc::UNKNOWN, pixels)) return failed("write");
  if (!output->close()) return failed("finish");
  data.assign(bytes.begin(), bytes.end());
  return true;
}

// Checks that an image can be saved: a known extension, pixels for its size,
// all finite.
static bool check_image_to_save(
    const std::string& filename, const texture_data& image, std::string& error) {
  if (!is_image_filename(filename)) {
    error = filename + ": unknown image extension \"" + path_extension(filename) +
            "\" (use exr, hdr, pfm, png or jpg)";
    return false;
  }
  if (image.width <= 0 || image.height <= 0 ||
      image.pixels.size() != (size_t)image.width * (size_t)image.height) {
    error = filename + ": cannot save image: " + std::to_string(image.pixels.size()) +
            " pixels for size " + std::to_string(image.width) + "x" +
            std::to_string(image.height);
    return false;
  }
  for (size_t i = 0; i < image.pixels.size(); i++) {
    if (!isfinite(image.pixels[i])) {
      error = filename + ": cannot save image: pixel (" +
              std::to_string(i % image.width) + ", " + std::to_string(i / image.width) +
              ") is not finite";
      return false;
    }
  }
  return true;
}

// Encodes an image in memory: the bytes then go to disk through
// save_binary, which checks the write (OpenImageIO does not report a failed
// write of some formats, and libjpeg ends the program on one).
static bool encode_image(const std::string& filename, const texture_data& image,
    std::string& data, std::string& error, float exposure) {
  if (!check_image_to_save(filename, image, error)) return false;
  auto extension = path_extension(filename);
  if (extension == ".pfm") return encode_pfm(image, data), true;
  if (is_linear_extension(extension)) {
    auto spec = OIIO::ImageSpec(image.width, image.height, 3, OIIO::TypeDesc::FLOAT);
    return encode_with_oiio(filename, "image", spec, image.pixels.data(), data, error);
  }
  auto spec = OIIO::ImageSpec(image.width, image.height, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("oiio:ColorSpace", "sRGB");
  auto scale  = std::exp2(exposure);
  auto pixels = std::vector<uint8_t>(image.pixels.size() * 3);
  for (size_t i = 0; i < image.pixels.size(); i++) {
    for (auto c = 0; c < 3; c++) {
      auto value = std::clamp(image.pixels[i][c] * scale, 0.0f, 1.0f);
      pixels[i * 3 + c] = (uint8_t)std::lround(linear_to_srgb(value) * 255);
    }
  }
  return encode_with_oiio(filename, "image", spec, pixels.data(), data, error);
}

bool save_image(const std::string& filename, const texture_data& image,
    std::string& error, float exposure, bool replace) {
  auto data = std::string{};
  if (!encode_image(filename, image, data, error, exposure)) return false;
  return save_binary(filename, data, error, replace);
}

bool save_image_layers(const std::string& filename, const texture_data& image,
    const std::vector<image_layer>& layers, std::string& error, bool replace) {
  if (path_extension(filename) != ".exr") {
    error = filename + ": image layers are saved in OpenEXR only: use a name ending in .exr";
    return false;
  }
  if (!check_image_to_save(filename, image, error)) return false;
  auto data     = std::string{};
  auto pixels   = image.pixels.size();
  auto channels = 3;
  auto spec     = OIIO::ImageSpec(image.width, image.height, 3, OIIO::TypeDesc::FLOAT);
  for (auto& layer : layers) {
    if (layer.channels.empty() || layer.pixels.size() != pixels * layer.channels.size()) {
      error = filename + ": cannot save layer " + layer.name + ": " +
              std::to_string(layer.pixels.size()) + " values for " +
              std::to_string(pixels) + " pixels of " +
              std::to_string(layer.channels.size()) + " channels";
      return false;
    }
    for (size_t i = 0; i < layer.pixels.size(); i++) {
      if (!std::isfinite(layer.pixels[i])) {
        auto pixel = i / layer.channels.size();
        error = filename + ": cannot save layer " + layer.name + ": pixel (" +
                std::to_string(pixel % image.width) + ", " +
                std::to_string(pixel / image.width) + ") is not finite";
        return false;
      }
    }
    for (auto& channel : layer.channels) spec.channelnames.push_back(layer.name + "." + channel);
    channels += (int)layer.channels.size();
  }
  spec.nchannels = channels;
  spec.attribute("compression", "zip");
  auto values = std::vector<float>(pixels * channels);
  for (size_t i = 0; i < pixels; i++) {
    auto out = &values[i * channels];
    for (auto c = 0; c < 3; c++) *out++ = image.pixels[i][c];
    for (auto& layer : layers) {
      auto count = layer.channels.size();
      for (size_t c = 0; c < count; c++) *out++ = layer.pixels[i * count + c];
    }
  }
  if (!encode_with_oiio(filename, "image", spec, values.data(), data, error)) return false;
  return save_binary(filename, data, error, replace);
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// RENDER PARTS
// -----------------------------------------------------------------------------
namespace yocto {

static const auto render_part_format = std::string{"yocto-hair render part 1"};
static const auto render_part_channels = std::array<std::string, 3>{"R", "G", "B"};

// The name of the channel with bits 32 half ... 32 half + 31 of channel c.
// Extra sum k: "extra.K." before the same names.
static std::string render_part_channel(int c, int half, int extra = -1) {
  auto prefix = extra < 0 ? std::string{"sum."} : "extra." + std::to_string(extra) + ".";
  return prefix + render_part_channels[c] + "." + std::to_string(half);
}

static std::string render_part_range(const render_part& part) {
  return std::to_string(part.first) + ":" + std::to_string(part.first + part.count);
}

static uint64_t render_part_checksum(const render_part& part) {
  auto stream = hash_stream{};
  hash_bytes(stream, render_part_format.data(), render_part_format.size());
  hash_bytes(stream, part.settings.data(), part.settings.size());
  for (auto value : {(int64_t)part.samples, (int64_t)part.first, (int64_t)part.count,
           (int64_t)part.width, (int64_t)part.height, part.rays, part.nonfinite})
    hash_word(stream, (uint64_t)value);
  hash_bytes(stream, part.sums.data(), part.sums.size() * sizeof(fixed_sum3));
  // Parts without extra sums keep the checksums they always had.
  if (part.extra > 0) {
    hash_word(stream, (uint64_t)part.extra);
    hash_bytes(stream, part.extra_sums.data(), part.extra_sums.size() * sizeof(fixed_sum3));
  }
  return stream.hash;
}

std::string hex_string(uint64_t value) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%016llx", (unsigned long long)value);
  return buffer;
}

bool save_render_part(const std::string& filename, const render_part& part,
    std::string& error, bool replace) {
  if (path_extension(filename) != ".exr") {
    error = filename + ": a render part is an OpenEXR image: use a name ending in .exr";
    return false;
  }
  if (part.width <= 0 || part.height <= 0 || part.count <= 0 ||
      part.sums.size() != (size_t)part.width * (size_t)part.height) {
    error = filename + ": cannot save a render part without samples or pixels";
    return false;
  }
  if (part.extra < 0 || part.extra_sums.size() != part.sums.size() * part.extra) {
    error = filename + ": cannot save a render part whose extra sums do not fit its pixels";
    return false;
  }
  // R, G, B as floats, then the words as 32-bit halves: the sums', then each
  // extra sum's.
  auto sums     = 1 + part.extra;
  auto channels = 3 + 18 * sums;
  auto spec     = OIIO::ImageSpec(part.width, part.height, channels, OIIO::TypeDesc::FLOAT);
  spec.channelnames.assign(render_part_channels.begin(), render_part_channels.end());
  spec.channelformats.assign(3, OIIO::TypeDesc::FLOAT);
  for (auto k = -1; k < part.extra; k++) {
    for (auto c = 0; c < 3; c++) {
      for (auto half = 0; half < 6; half++) {
        spec.channelnames.push_back(render_part_channel(c, half, k));
        spec.channelformats.push_back(OIIO::TypeDesc::UINT32);
      }
    }
  }
  spec.attribute("compression", "zip");
  spec.attribute("yocto:part", render_part_format);
  spec.attribute("yocto:settings", part.settings);
  spec.attribute("yocto:samples", std::to_string(part.samples));
  spec.attribute("yocto:range", render_part_range(part));
  spec.attribute("yocto:rays", std::to_string(part.rays));
  spec.attribute("yocto:nonfinite", std::to_string(part.nonfinite));
  if (part.extra > 0) spec.attribute("yocto:extra", std::to_string(part.extra));
  spec.attribute("yocto:checksum", hex_string(render_part_checksum(part)));
  // Pixels in the native layout: 3 floats, then 18 unsigned ints a sum.
  auto pixel_words = (size_t)channels;
  static_assert(render_part_pixel_bytes == 4 * (3 + 18) && render_part_extra_bytes == 4 * 18);
  auto pixels = std::vector<uint32_t>(part.sums.size() * pixel_words);
  for (size_t i = 0; i < part.sums.size(); i++) {
    auto out  = &pixels[i * pixel_words];
    auto mean = glm::vec3(fixed_to_double(part.sums[i]) / (double)part.count);
    std::memcpy(out, &mean[0], 3 * sizeof(float));
    out += 3;
    for (auto k = -1; k < part.extra; k++) {
      auto& sum = k < 0 ? part.sums[i] : part.extra_sums[i * part.extra + k];
      for (auto word = 0; word < 9; word++) {
        *out++ = (uint32_t)sum.words[word];
        *out++ = (uint32_t)(sum.words[word] >> 32);
      }
    }
  }
  auto data = std::string{};
  if (!encode_with_oiio(filename, "render part", spec, pixels.data(), data, error)) return false;
  return save_binary(filename, data, error, replace);
}

// A whole decimal number from an attribute, or false.
static bool parse_part_number(const std::string& text, int64_t& value) {
  auto end    = text.data() + text.size();
  auto result = std::from_chars(text.data(), end, value);
  return !text.empty() && result.ec == std::errc{} && result.ptr == end;
}

bool load_render_part(const std::string& filename, render_part& part, std::string& error) {
  part           = {};
  auto file_size = (size_t)0;
  if (!check_input_file(filename, file_size, error)) return false;
  auto input = OIIO::ImageInput::open(filename);
  if (!input) {
    auto message = OIIO::geterror();
    error = filename + ": cannot open render part" + (message.empty() ? "" : " (" + message + ")");
    return false;
  }
  auto& spec     = input->spec();
  auto  not_part = [&](const std::string& what) {
    error = filename + ": not a render part of yocto-hair (" + what + ")";
    return false;
  };
  if (spec.get_string_attribute("yocto:part") != render_part_format)
    return not_part("no yocto:part attribute \"" + render_part_format + "\"");
  auto samples = (int64_t)0, first = (int64_t)0, end = (int64_t)0;
  auto range   = std::string(spec.get_string_attribute("yocto:range"));
  auto colon   = range.find(':');
  if (!parse_part_number(spec.get_string_attribute("yocto:samples"), samples) ||
      colon == std::string::npos || !parse_part_number(range.substr(0, colon), first) ||
      !parse_part_number(range.substr(colon + 1), end) ||
      !parse_part_number(spec.get_string_attribute("yocto:rays"), part.rays) ||
      !parse_part_number(spec.get_string_attribute("yocto:nonfinite"), part.nonfinite))
    return not_part("bad yocto:samples, yocto:range, yocto:rays or yocto:nonfinite");
  if (samples <= 0 || samples > std::numeric_limits<int>::max() || first < 0 ||
      end <= first || end > samples) {
    error = filename + ": sample range " + range + " is not within the render's " +
            std::to_string(samples) + " samples";
    return false;
  }
  part.samples  = (int)samples;
  part.first    = (int)first;
  part.count    = (int)(end - first);
  part.settings = std::string(spec.get_string_attribute("yocto:settings"));
  part.width    = spec.width;
  part.height   = spec.height;
  // Where each channel is in a native pixel.
  auto offsets = std::vector<size_t>(spec.nchannels);
  for (auto c = 1; c < spec.nchannels; c++)
    offsets[c] = offsets[c - 1] + spec.channelformat(c - 1).size();
  auto extra = (int64_t)0;
  if (spec.find_attribute("yocto:extra") &&
      (!parse_part_number(spec.get_string_attribute("yocto:extra"), extra) || extra < 1 ||
          extra > 64))
    return not_part("bad yocto:extra");
  part.extra       = (int)extra;
  auto sum_offsets = std::vector<size_t>(18 * (1 + part.extra));
  for (auto k = -1; k < part.extra; k++) {
    for (auto c = 0; c < 3; c++) {
      for (auto half = 0; half < 6; half++) {
        auto name  = render_part_channel(c, half, k);
        auto found = std::find(spec.channelnames.begin(), spec.channelnames.end(), name);
        if (found == spec.channelnames.end()) return not_part("no channel " + name);
        auto index = (int)(found - spec.channelnames.begin());
        if (spec.channelformat(index) != OIIO::TypeDesc::UINT32)
          return not_part("channel " + name + " is not 32-bit unsigned");
        sum_offsets[18 * (k + 1) + 6 * c + half] = offsets[index];
      }
    }
  }
  if (spec.width <= 0 || spec.height <= 0 || spec.depth > 1) return not_part("no pixels");
  auto pixels      = (double)spec.width * (double)spec.height;
  auto pixel_bytes = spec.pixel_bytes(true);
  if (!check_load_memory(filename,
          "a " + std::to_string(spec.width) + "x" + std::to_string(spec.height) + " render part",
          pixels * ((double)pixel_bytes + (1 + part.extra) * sizeof(fixed_sum3)), error))
    return false;
  auto buffer = std::vector<unsigned char>((size_t)pixels * pixel_bytes);
  if (!input->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UNKNOWN, buffer.data())) {
    error = filename + ": cannot read render part (" + input->geterror() + ")";
    return false;
  }
  input->close();
  part.sums.resize((size_t)pixels);
  part.extra_sums.resize((size_t)pixels * part.extra);
  for (size_t i = 0; i < part.sums.size(); i++) {
    auto pixel = buffer.data() + i * pixel_bytes;
    for (auto k = -1; k < part.extra; k++) {
      auto& sum     = k < 0 ? part.sums[i] : part.extra_sums[i * part.extra + k];
      auto  offsets = &sum_offsets[18 * (k + 1)];
      for (auto word = 0; word < 9; word++) {
        uint32_t low, high;
        std::memcpy(&low, pixel + offsets[2 * word], 4);
        std::memcpy(&high, pixel + offsets[2 * word + 1], 4);
        sum.words[word] = (uint64_t)high << 32 | low;
      }
    }
  }
  if (spec.get_string_attribute("yocto:checksum") != hex_string(render_part_checksum(part))) {
    error = filename + ": render part is damaged (its checksum does not match its contents)";
    part  = {};
    return false;
  }
  return true;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// JSON SCENES: LOADING
// -----------------------------------------------------------------------------
namespace yocto {

// Ordered so that elements keyed by name (4.0 layout) keep the file's order.
using json = nlohmann::ordered_json;

// What a material element said, kept until instances tell which materials
// dress fibers: that decides the type of a material without one.
struct json_material_info {
  bool                     has_type      = false;
  bool                     has_hair_keys = false;
  bool                     has_color     = false;
  std::vector<std::string> keys          = {};
  std::vector<std::string> hair_given    = {};  // hair parameters given, by name
};

// Everything load_scene needs besides the scene: where files are, what the
// elements referred to, and the messages.
struct json_loader {
  std::string                     filename       = "";
  std::string                     dirname        = "";
  std::string                     error          = "";
  std::vector<std::string>        warnings       = {};
  std::vector<std::string>        shape_uris     = {};
  std::vector<std::string>        shape_users    = {};  // who named it first
  std::vector<std::string>        texture_uris   = {};  // "" is textures/NAME.*
  std::vector<std::string>        texture_users  = {};
  std::vector<json_material_info> material_infos = {};
};

static bool json_fail(json_loader& loader, const std::string& message) {
  loader.error = loader.filename + ": " + message;
  return false;
}

static void json_warn(json_loader& loader, const std::string& message) {
  loader.warnings.push_back(loader.filename + ": " + message);
}

static std::string json_key(const std::string& element, const std::string& key) {
  return element + ": key \"" + key + "\"";
}

static std::string json_describe(const json& value) {
  if (value.is_array()) return "an array of " + std::to_string(value.size()) + " values";
  if (value.is_string()) return "the string \"" + value.get<std::string>() + "\"";
  if (value.is_boolean()) return value.get<bool>() ? "true" : "false";
  if (value.is_number()) return value.dump();
  return std::string("a ") + value.type_name();
}

static bool read_number(json_loader& loader, const json& value, const std::string& where,
    float& number, float min = flt_min, float max = flt_max, bool open_min = false) {
  if (!value.is_number())
    return json_fail(loader, where + ": expected a number, got " + json_describe(value));
  number = (float)value.get<double>();
  if (!std::isfinite(number))
    return json_fail(loader, where + ": " + value.dump() + " is not a finite float");
  if (number < min || number > max || (open_min && number == min)) {
    auto range = std::string{};
    if (max == flt_max) range = (open_min ? "> " : ">= ") + format_float(min);
    else range = "in [" + format_float(min) + ", " + format_float(max) + "]";
    return json_fail(loader, where + ": expected a number " + range + ", got " +
                                 format_float(number));
  }
  return true;
}

static bool read_numbers(json_loader& loader, const json& value, const std::string& where,
    float* numbers, int count, float min = flt_min, float max = flt_max) {
  if (!value.is_array() || value.size() != (size_t)count)
    return json_fail(loader, where + ": expected an array of " + std::to_string(count) +
                                 " numbers, got " + json_describe(value));
  for (auto i = 0; i < count; i++)
    if (!read_number(loader, value[i], where, numbers[i], min, max)) return false;
  return true;
}

static bool read_vec3(json_loader& loader, const json& value, const std::string& where,
    vec3f& v, float min = flt_min, float max = flt_max) {
  return read_numbers(loader, value, where, &v.x, 3, min, max);
}

// A frame is 12 numbers: the x, y and z axes, then the origin.
static bool read_frame(
    json_loader& loader, const json& value, const std::string& where, frame3f& frame) {
  float numbers[12];
  if (!read_numbers(loader, value, where, numbers, 12)) return false;
  frame = {{numbers[0], numbers[1], numbers[2]}, {numbers[3], numbers[4], numbers[5]},
      {numbers[6], numbers[7], numbers[8]}, {numbers[9], numbers[10], numbers[11]}};
  return true;
}

// A lookat is 9 numbers: from, to, up. Degenerate ones would make NaN axes.
static bool read_lookat(json_loader& loader, const json& value, const std::string& where,
    frame3f& frame, float& distance) {
  float numbers[9];
  if (!read_numbers(loader, value, where, numbers, 9)) return false;
  auto from = vec3f{numbers[0], numbers[1], numbers[2]};
  auto to   = vec3f{numbers[3], numbers[4], numbers[5]};
  auto up   = vec3f{numbers[6], numbers[7], numbers[8]};
  distance  = length(from - to);
  if (!(distance > 0)) return json_fail(loader, where + ": from and to coincide");
  if (!(length(cross(up, normalize(from - to))) > 1e-6f * length(up)))
    return json_fail(loader, where + ": up is zero or parallel to the view direction");
  frame = lookat_frame(from, to, up);
  return true;
}

static bool read_bool(
    json_loader& loader, const json& value, const std::string& where, bool& flag) {
  if (!value.is_boolean())
    return json_fail(loader, where + ": expected true or false, got " + json_describe(value));
  flag = value.get<bool>();
  return true;
}

static bool read_string(
    json_loader& loader, const json& value, const std::string& where, std::string& text) {
  if (!value.is_string())
    return json_fail(loader, where + ": expected a string, got " + json_describe(value));
  text = value.get<std::string>();
  return true;
}

static bool read_count(
    json_loader& loader, const json& value, const std::string& where, int& count) {
  if (!value.is_number_integer() || value.get<int64_t>() < 0 ||
      value.get<int64_t>() > std::numeric_limits<int>::max())
    return json_fail(loader, where + ": expected a non-negative integer, got " +
                                 json_describe(value));
  count = (int)value.get<int64_t>();
  return true;
}

enum struct json_reference { shape, texture, material };

// A reference is an index (4.2 layout) or a name (4.0 layout). A name with
// no element makes one for shapes and textures, whose files are then found
// by name (shapes/NAME.ply, textures/NAME.*), as Yocto 4.0 did.
static bool read_reference(json_loader& loader, scene_data& scene, const json& value,
    const std::string& where, const std::string& user, json_reference kind, int& index) {
  auto& names = kind == json_reference::shape     ? scene.shape_names
                : kind == json_reference::texture ? scene.texture_names
                                                  : scene.material_names;
  auto  what  = kind == json_reference::shape     ? std::string("shape")
                : kind == json_reference::texture ? std::string("texture")
                                                  : std::string("material");
  if (value.is_number_integer()) {
    auto number = value.get<int64_t>();
    if (number == -1 && kind == json_reference::texture) {
      index = -1;
      return true;
    }
    if (number < 0 || number >= (int64_t)names.size())
      return json_fail(loader, where + ": " + what + " reference " + value.dump() +
                                   " out of range (" + std::to_string(names.size()) +
                                   " " + what + "s)");
    index = (int)number;
    return true;
  }
  if (!value.is_string())
    return json_fail(loader, where + ": expected a " + what +
                                 " index or name, got " + json_describe(value));
  auto name  = value.get<std::string>();
  auto found = std::find(names.begin(), names.end(), name);
  if (found != names.end()) {
    index = (int)(found - names.begin());
    return true;
  }
  if (kind == json_reference::material)
    return json_fail(loader, where + ": unknown material \"" + name + "\"");
  index = (int)names.size();
  names.push_back(name);
  if (kind == json_reference::shape) {
    scene.shapes.emplace_back();
    loader.shape_uris.push_back("shapes/" + name + ".ply");
    loader.shape_users.push_back(user);
  } else {
    scene.textures.emplace_back();
    loader.texture_uris.push_back("");
    loader.texture_users.push_back(user);
  }
  return true;
}

// Calls parse(element, name, label) for each element of a group: an array of
// objects (4.2 layout) or an object keyed by name (4.0 layout).
template <typename Parse>
static bool parse_group(json_loader& loader, const json& group,
    const std::string& group_name, const std::string& kind, Parse&& parse) {
  if (group.is_array()) {
    for (size_t i = 0; i < group.size(); i++) {
      auto& element = group[i];
      auto  label   = kind + " " + std::to_string(i);
      if (!element.is_object())
        return json_fail(loader, label + ": expected an object, got " + json_describe(element));
      auto name = std::string{};
      if (element.contains("name") &&
          !read_string(loader, element["name"], json_key(label, "name"), name))
        return false;
      if (!name.empty()) label = kind + " \"" + name + "\"";
      if (!parse(element, name, label)) return false;
    }
    return true;
  }
  if (group.is_object()) {
    for (auto& [name, element] : group.items()) {
      auto label = kind + " \"" + name + "\"";
      if (!element.is_object())
        return json_fail(loader, label + ": expected an object, got " + json_describe(element));
      if (!parse(element, name, label)) return false;
    }
    return true;
  }
  return json_fail(loader, "group \"" + group_name +
                               "\": expected an array or an object, got " +
                               json_describe(group));
}

static void warn_unknown_key(
    json_loader& loader, const std::string& label, const std::string& key) {
  json_warn(loader, label + ": unknown key \"" + key + "\" ignored");
}

static bool parse_camera(json_loader& loader, const json& element,
    const std::string& label, camera_data& camera) {
  auto has_focus = false, has_frame = false, has_lookat = false;
  auto distance  = 0.0f;
  for (auto& [key, value] : element.items()) {
    auto where = json_key(label, key);
    auto ok    = true;
    if (key == "name") continue;
    else if (key == "lens") ok = read_number(loader, value, where, camera.lens, 0, flt_max, true);
    else if (key == "film") ok = read_number(loader, value, where, camera.film, 0, flt_max, true);
    else if (key == "aspect")
      ok = read_number(loader, value, where, camera.aspect, 0, flt_max, true);
    else if (key == "focus")
      ok = has_focus = read_number(loader, value, where, camera.focus, 0, flt_max, true);
    else if (key == "aperture") ok = read_number(loader, value, where, camera.aperture, 0);
    else if (key == "orthographic") ok = read_bool(loader, value, where, camera.orthographic);
    else if (key == "frame") ok = has_frame = read_frame(loader, value, where, camera.frame);
    else if (key == "lookat")
      ok = has_lookat = read_lookat(loader, value, where, camera.frame, distance);
    else warn_unknown_key(loader, label, key);
    if (!ok) return false;
  }
  if (has_frame && has_lookat)
    return json_fail(loader, label + ": has both \"frame\" and \"lookat\"");
  // As Yocto/GL: a camera placed by lookat focuses on its target.
  if (has_lookat && !has_focus) camera.focus = distance;
  return true;
}

static bool parse_environment(json_loader& loader, scene_data& scene,
    const json& element, const std::string& label, environment_data& environment) {
  for (auto& [key, value] : element.items()) {
    auto where = json_key(label, key);
    auto ok    = true;
    if (key == "name") continue;
    else if (key == "emission") ok = read_vec3(loader, value, where, environment.emission, 0);
    else if (key == "emission_tex")
      ok = read_reference(loader, scene, value, where, label, json_reference::texture,
          environment.emission_tex);
    else if (key == "frame") ok = read_frame(loader, value, where, environment.frame);
    else warn_unknown_key(loader, label, key);
    if (!ok) return false;
  }
  return true;
}

static bool parse_instance(json_loader& loader, scene_data& scene, const json& element,
    const std::string& label, instance_data& instance) {
  auto has_frame = false, has_lookat = false;
  auto distance  = 0.0f;
  for (auto& [key, value] : element.items()) {
    auto where = json_key(label, key);
    auto ok    = true;
    if (key == "name") continue;
    else if (key == "frame") ok = has_frame = read_frame(loader, value, where, instance.frame);
    else if (key == "lookat") {
      ok = has_lookat = read_lookat(loader, value, where, instance.frame, distance);
      // As Yocto/GL: an object placed by lookat points its +z at the target
      // (a camera points -z), so an area light's front faces what it lights.
      instance.frame.x = -instance.frame.x;
      instance.frame.z = -instance.frame.z;
    } else if (key == "shape")
      ok = read_reference(
          loader, scene, value, where, label, json_reference::shape, instance.shape);
    else if (key == "material")
      ok = read_reference(
          loader, scene, value, where, label, json_reference::material, instance.material);
    else warn_unknown_key(loader, label, key);
    if (!ok) return false;
  }
  if (has_frame && has_lookat)
    return json_fail(loader, label + ": has both \"frame\" and \"lookat\"");
  if (!element.contains("shape")) return json_fail(loader, label + ": no \"shape\" given");
  if (!element.contains("material"))
    return json_fail(loader, label + ": no \"material\" given");
  return true;
}

// Yocto/GL material types we do not model, mapped to the nearest we do.
static bool parse_material_type(json_loader& loader, const json& value,
    const std::string& where, material_type& type) {
  auto name = std::string{};
  if (!read_string(loader, value, where, name)) return false;
  for (auto t = 0; t < (int)material_type_names.size(); t++) {
    if (name == material_type_names[t]) {
      type = (material_type)t;
      return true;
    }
  }
  static const auto glossy_like = std::unordered_set<std::string>{
      "plastic", "metal", "metallic", "reflective", "gltfpbr", "coated"};
  static const auto matte_like = std::unordered_set<std::string>{"transparent",
      "refractive", "subsurface", "volumetric", "thinglass", "glass", "passthrough"};
  if (glossy_like.count(name) || matte_like.count(name)) {
    type = glossy_like.count(name) ? material_type::glossy : material_type::matte;
    json_warn(loader, where + ": material type \"" + name + "\" is not supported, using " +
                          material_type_names[(int)type]);
    return true;
  }
  return json_fail(loader, where + ": unknown material type \"" + name +
                               "\" (expected matte, glossy or hair)");
}

// A hair parameter's value, checked against its range in hair_parameters.
static bool read_hair_parameter(json_loader& loader, const json& value,
    const std::string& where, const hair_parameter& parameter, vec3f& result) {
  auto count = parameter.kind == hair_parameter_kind::number ? 1 : 3;
  if (count == 1 && !value.is_number())
    return json_fail(loader, where + ": expected a number, got " + json_describe(value));
  if (count == 3 && (!value.is_array() || value.size() != 3))
    return json_fail(loader, where + ": expected an array of 3 numbers, got " +
                                 json_describe(value));
  for (auto c = 0; c < count; c++) {
    auto& number = count == 1 ? value : value[c];
    if (!number.is_number())
      return json_fail(loader, where + ": expected a number, got " + json_describe(number));
    result[c] = (float)number.get<double>();
    if (!std::isfinite(result[c]))
      return json_fail(loader, where + ": " + number.dump() + " is not a finite float");
    if (!is_hair_parameter_valid(parameter, vec3f{result[c]}))
      return json_fail(loader, where + ": expected " + (count == 1 ? "a number " : "numbers ") +
                                   format_hair_parameter_range(parameter) + ", got " +
                                   format_float(result[c]));
  }
  if (count == 1) result = vec3f{result.x};
  return true;
}

static bool parse_material(json_loader& loader, scene_data& scene, const json& element,
    const std::string& label, material_data& material, json_material_info& info) {
  auto& hair = material.hair;
  for (auto& [key, value] : element.items()) {
    auto where = json_key(label, key);
    auto ok    = true;
    if (key == "name") continue;
    info.keys.push_back(key);
    // "color" is every type's: it goes to the hair in finish_material.
    auto parameter = key != "color" ? find_hair_parameter(key) : nullptr;
    info.has_hair_keys |= parameter != nullptr;
    if (parameter) {
      auto number = vec3f{0, 0, 0};
      ok = read_hair_parameter(loader, value, where, *parameter, number);
      if (ok) set_hair_parameter(hair, *parameter, number);
      info.hair_given.push_back(parameter->name);
    } else if (key == "type") {
      ok = info.has_type = parse_material_type(loader, value, where, material.type);
    } else if (key == "emission") {
      ok = read_vec3(loader, value, where, material.emission, 0);
    } else if (key == "color") {
      ok = info.has_color = read_vec3(loader, value, where, material.color, 0);
    } else if (key == "roughness") {
      ok = read_number(loader, value, where, material.roughness, 0, 1);
    } else if (key == "ior") {
      ok = read_number(loader, value, where, material.ior, 0, flt_max, true);
    } else if (key == "emission_tex") {
      ok = read_reference(
          loader, scene, value, where, label, json_reference::texture, material.emission_tex);
    } else if (key == "color_tex") {
      ok = read_reference(
          loader, scene, value, where, label, json_reference::texture, material.color_tex);
    } else {
      info.keys.pop_back();
      warn_unknown_key(loader, label, key);
    }
    if (!ok) return false;
  }
  return true;
}

// Once the type is known: hair takes the colour as its own, each type drops
// (with a warning) the keys it does not use, and the pigment defaults apply.
static bool finish_material(json_loader& loader, const std::string& label,
    material_data& material, const json_material_info& info) {
  auto used = [&](const std::string& key) {
    if (key == "type" || key == "emission" || key == "emission_tex" || key == "color")
      return true;
    switch (material.type) {
      case material_type::matte: return key == "color_tex";
      case material_type::glossy:
        return key == "color_tex" || key == "roughness" || key == "ior";
      case material_type::hair: return find_hair_parameter(key) != nullptr;
    }
    return false;
  };
  for (auto& key : info.keys) {
    if (!used(key))
      json_warn(loader, label + ": key \"" + key + "\" is not used by " +
                            material_type_names[(int)material.type] +
                            " materials, ignored");
  }
  auto defaults = material_data{};
  if (material.type == material_type::hair) {
    if (info.has_color) {
      auto& color = *find_hair_parameter("color");
      for (auto c = 0; c < 3; c++)
        if (!is_hair_parameter_valid(color, vec3f{material.color[c]}))
          return json_fail(loader, json_key(label, "color") + ": a hair colour must be " +
                                       format_hair_parameter_range(color) + ", got " +
                                       format_float(material.color[c]));
      set_hair_parameter(material.hair, color, material.color);
    }
    // pbrt's rule: one pigment given means the other is 0.
    auto given = [&](const std::string& name) {
      return std::find(info.hair_given.begin(), info.hair_given.end(), name) !=
             info.hair_given.end();
    };
    if (given("pheomelanin") && !given("eumelanin")) material.hair.eumelanin = 0;
    if (given("eumelanin") && !given("pheomelanin")) material.hair.pheomelanin = 0;
    material.color     = defaults.color;
    material.color_tex = defaults.color_tex;
    material.roughness = defaults.roughness;
    material.ior       = defaults.ior;
  } else {
    material.hair = defaults.hair;
    if (material.type == material_type::matte) {
      material.roughness = defaults.roughness;
      material.ior       = defaults.ior;
    }
  }
  return true;
}

static bool parse_asset(json_loader& loader, scene_data& scene, const json& asset) {
  if (!asset.is_object())
    return json_fail(loader, "group \"asset\": expected an object, got " + json_describe(asset));
  for (auto& [key, value] : asset.items()) {
    if (key == "copyright") {
      if (!read_string(loader, value, json_key("asset", key), scene.copyright)) return false;
    } else if (key != "version" && key != "generator") {
      warn_unknown_key(loader, "asset", key);
    }
  }
  return true;
}

static bool parse_settings(json_loader& loader, scene_data& scene, const json& settings) {
  if (!settings.is_object())
    return json_fail(loader, "group \"settings\": expected an object, got " +
                                 json_describe(settings));
  for (auto& [key, value] : settings.items()) {
    auto where = json_key("settings", key);
    auto ok    = true;
    if (key == "resolution") ok = read_count(loader, value, where, scene.settings.resolution);
    else if (key == "samples") ok = read_count(loader, value, where, scene.settings.samples);
    else if (key == "bounces") ok = read_count(loader, value, where, scene.settings.bounces);
    else warn_unknown_key(loader, "settings", key);
    if (!ok) return false;
  }
  return true;
}

// A file reference of a texture or shape element; 4.0 groups keyed by name
// may leave it out and use the default place.
static bool parse_file_element(json_loader& loader, const json& element,
    const std::string& label, bool uri_required, std::string& uri) {
  for (auto& [key, value] : element.items()) {
    if (key == "name") continue;
    if (key == "uri") {
      if (!read_string(loader, value, json_key(label, key), uri)) return false;
    } else {
      warn_unknown_key(loader, label, key);
    }
  }
  if (uri_required && uri.empty()) return json_fail(loader, label + ": no \"uri\" given");
  return true;
}

// Finds textures/NAME.EXT for a texture that a 4.0 scene names without a file.
static bool find_texture_file(json_loader& loader, const std::string& name,
    const std::string& label, std::string& uri) {
  static const char* extensions[] = {".hdr", ".exr", ".png", ".jpg", ".jpeg", ".pfm"};
  for (auto extension : extensions) {
    auto candidate = "textures/" + name + extension;
    auto ec        = std::error_code{};
    if (std::filesystem::is_regular_file(path_join(loader.dirname, candidate), ec)) {
      uri = candidate;
      return true;
    }
  }
  return json_fail(loader, label + ": no image file textures/" + name +
                               ".{hdr,exr,png,jpg,jpeg,pfm} in " +
                               (loader.dirname.empty() ? "." : loader.dirname));
}

// The type of a material that names none: hair keys make it hair, and so
// does dressing fibers alone; anything else is matte.
static material_type infer_material_type(const scene_data& scene, int material,
    const json_material_info& info) {
  if (info.has_hair_keys) return material_type::hair;
  auto used = false, fibers_only = true;
  for (auto& instance : scene.instances) {
    if (instance.material != material) continue;
    used = true;
    fibers_only &= is_fiber(scene.shapes[instance.shape]);
  }
  return used && fibers_only ? material_type::hair : material_type::matte;
}

// Elements that name the same file (the path resolved) merge into the first
// of them: returns each element's new index, and keeps one entry per file in
// `elements` and in the parallel arrays, the first of which holds the paths.
template <typename T>
static std::vector<int> merge_same_files(
    std::vector<T>& elements, const std::vector<std::vector<std::string>*>& arrays) {
  auto& paths = *arrays.front();
  auto  first = std::unordered_map<std::string, int>{};
  auto  index = std::vector<int>(elements.size());
  auto  kept  = 0;
  for (auto i = 0; i < (int)elements.size(); i++) {
    auto ec  = std::error_code{};
    auto key = std::filesystem::weakly_canonical(paths[i], ec).string();
    if (ec) key = paths[i];
    auto [found, added] = first.try_emplace(key, kept);
    index[i]            = found->second;
    if (!added) continue;
    if (kept != i) {
      elements[kept] = std::move(elements[i]);
      for (auto array : arrays) (*array)[kept] = std::move((*array)[i]);
    }
    kept++;
  }
  elements.resize(kept);
  for (auto array : arrays) array->resize(kept);
  return index;
}

// Line and column of a byte offset, for json syntax errors.
static std::string text_position(const std::string& text, size_t byte) {
  auto line = 1, column = 1;
  for (size_t i = 0; i < byte && i < text.size(); i++) {
    if (text[i] == '\n') line++, column = 1;
    else column++;
  }
  return "line " + std::to_string(line) + ", column " + std::to_string(column);
}

// nlohmann's SAX events, ignored but for the error: its position is what
// the DOM parser's exception lacks for a number out of double range.
struct json_error_locator {
  size_t      position = 0;
  std::string token    = "";
  bool null() { return true; }
  bool boolean(bool) { return true; }
  bool number_integer(json::number_integer_t) { return true; }
  bool number_unsigned(json::number_unsigned_t) { return true; }
  bool number_float(json::number_float_t, const std::string&) { return true; }
  bool string(std::string&) { return true; }
  bool binary(json::binary_t&) { return true; }
  bool start_object(size_t) { return true; }
  bool key(std::string&) { return true; }
  bool end_object() { return true; }
  bool start_array(size_t) { return true; }
  bool end_array() { return true; }
  bool parse_error(size_t byte, const std::string& last_token, const json::exception&) {
    position = byte;
    token    = last_token;
    return false;
  }
};

static bool load_scene_json(json_loader& loader, scene_data& scene) {
  auto text = std::string{};
  if (!load_text(loader.filename, text, loader.error)) return false;
  auto js = json{};
  // nlohmann reports the byte just past the error.
  auto place = [&](size_t byte) { return text_position(text, byte > 0 ? byte - 1 : 0); };
  try {
    js = json::parse(text);
  } catch (const json::parse_error& exception) {
    // Its message without its own prefix and position.
    auto message = std::string(exception.what());
    auto column  = message.find(", column ");
    auto colon   = message.find(": ", column == std::string::npos ? 0 : column);
    if (colon != std::string::npos) message = message.substr(colon + 2);
    return json_fail(loader, place(exception.byte) + ": malformed json: " + message);
  } catch (const json::exception& exception) {
    // A number beyond double range (1e999), located by parsing again: the
    // place is where the number starts.
    auto locator = json_error_locator{};
    json::sax_parse(text, &locator);
    if (exception.id != 406)
      return json_fail(loader, place(locator.position) + ": " + exception.what());
    auto start = locator.position - std::min(locator.position, locator.token.size());
    return json_fail(loader, text_position(text, start) + ": number " + locator.token +
                                 " is out of range");
  }
  if (!js.is_object())
    return json_fail(loader, "expected a json object at the top, got " + json_describe(js));

  // Groups go in dependency order, whatever their order in the file.
  static const auto known_groups = std::unordered_set<std::string>{"asset", "settings",
      "textures", "shapes", "materials", "cameras", "environments", "distant_lights",
      "instances", "objects"};
  for (auto& [key, value] : js.items())
    if (!known_groups.count(key)) json_warn(loader, "unknown group \"" + key + "\" ignored");
  auto group = [&](const char* name) -> const json* {
    auto found = js.find(name);
    return found == js.end() ? nullptr : &*found;
  };

  if (auto asset = group("asset"); asset && !parse_asset(loader, scene, *asset)) return false;
  if (auto settings = group("settings");
      settings && !parse_settings(loader, scene, *settings))
    return false;
  if (auto textures = group("textures")) {
    auto keyed = textures->is_object();
    auto ok    = parse_group(loader, *textures, "textures", "texture",
           [&](const json& element, const std::string& name, const std::string& label) {
          auto uri = std::string{};
          if (!parse_file_element(loader, element, label, !keyed, uri)) return false;
          scene.textures.emplace_back();
          scene.texture_names.push_back(name);
          loader.texture_uris.push_back(uri);
          loader.texture_users.push_back("");
          return true;
        });
    if (!ok) return false;
  }
  if (auto shapes = group("shapes")) {
    auto keyed = shapes->is_object();
    auto ok    = parse_group(loader, *shapes, "shapes", "shape",
           [&](const json& element, const std::string& name, const std::string& label) {
          auto uri = std::string{};
          if (!parse_file_element(loader, element, label, !keyed, uri)) return false;
          if (uri.empty()) uri = "shapes/" + name + ".ply";
          scene.shapes.emplace_back();
          scene.shape_names.push_back(name);
          loader.shape_uris.push_back(uri);
          loader.shape_users.push_back("");
          return true;
        });
    if (!ok) return false;
  }
  if (auto materials = group("materials")) {
    auto ok = parse_group(loader, *materials, "materials", "material",
        [&](const json& element, const std::string& name, const std::string& label) {
          auto material = material_data{};
          auto info     = json_material_info{};
          if (!parse_material(loader, scene, element, label, material, info)) return false;
          scene.materials.push_back(material);
          scene.material_names.push_back(name);
          loader.material_infos.push_back(info);
          return true;
        });
    if (!ok) return false;
  }
  if (auto cameras = group("cameras")) {
    auto ok = parse_group(loader, *cameras, "cameras", "camera",
        [&](const json& element, const std::string& name, const std::string& label) {
          auto camera = camera_data{};
          if (!parse_camera(loader, element, label, camera)) return false;
          scene.cameras.push_back(camera);
          scene.camera_names.push_back(name);
          return true;
        });
    if (!ok) return false;
  }
  if (auto environments = group("environments")) {
    auto ok = parse_group(loader, *environments, "environments", "environment",
        [&](const json& element, const std::string& name, const std::string& label) {
          auto environment = environment_data{};
          if (!parse_environment(loader, scene, element, label, environment)) return false;
          scene.environments.push_back(environment);
          scene.environment_names.push_back(name);
          return true;
        });
    if (!ok) return false;
  }
  if (auto lights = group("distant_lights")) {
    auto ok = parse_group(loader, *lights, "distant_lights", "distant light",
        [&](const json& element, const std::string&, const std::string& label) {
          auto light = distant_light_data{};
          for (auto& [key, value] : element.items()) {
            auto where = json_key(label, key);
            auto ok    = true;
            if (key == "name") continue;
            else if (key == "direction") ok = read_vec3(loader, value, where, light.direction);
            else if (key == "emission") ok = read_vec3(loader, value, where, light.emission, 0);
            else warn_unknown_key(loader, label, key);
            if (!ok) return false;
          }
          if (!(length(light.direction) > 0))
            return json_fail(loader, json_key(label, "direction") + ": is zero");
          scene.distant_lights.push_back(light);
          return true;
        });
    if (!ok) return false;
  }
  for (auto group_name : {"instances", "objects"}) {
    auto instances = group(group_name);
    if (!instances) continue;
    auto ok = parse_group(loader, *instances, group_name, "instance",
        [&](const json& element, const std::string& name, const std::string& label) {
          auto instance = instance_data{};
          if (!parse_instance(loader, scene, element, label, instance)) return false;
          scene.instances.push_back(instance);
          scene.instance_names.push_back(name);
          return true;
        });
    if (!ok) return false;
  }

  // Files, relative to the json's directory.
  auto element_label = [](const char* kind, const std::string& name,
                           const std::string& user, int index) {
    auto label = name.empty() ? std::string(kind) + " " + std::to_string(index)
                              : std::string(kind) + " \"" + name + "\"";
    return user.empty() ? label : label + " (used by " + user + ")";
  };
  auto shape_paths = std::vector<std::string>{}, shape_labels = std::vector<std::string>{};
  for (auto i = 0; i < (int)scene.shapes.size(); i++) {
    shape_paths.push_back(path_join(loader.dirname, loader.shape_uris[i]));
    shape_labels.push_back(element_label("shape", scene.shape_names[i], loader.shape_users[i], i));
  }
  auto texture_paths = std::vector<std::string>{}, texture_labels = std::vector<std::string>{};
  for (auto i = 0; i < (int)scene.textures.size(); i++) {
    auto label = element_label("texture", scene.texture_names[i], loader.texture_users[i], i);
    auto& uri  = loader.texture_uris[i];
    if (uri.empty() && !find_texture_file(loader, scene.texture_names[i], label, uri))
      return false;
    texture_paths.push_back(path_join(loader.dirname, uri));
    texture_labels.push_back(label);
  }
  // Each file is loaded once: elements naming the same file share one shape
  // or texture (a PLY named by 20000 shapes is one shape, and one BVH that
  // Embree instances), so memory is that of the distinct files.
  auto shape_index = merge_same_files(
      scene.shapes, {&shape_paths, &scene.shape_names, &shape_labels});
  for (auto& instance : scene.instances) instance.shape = shape_index[instance.shape];
  auto texture_index = merge_same_files(
      scene.textures, {&texture_paths, &scene.texture_names, &texture_labels});
  auto remap_texture = [&](int& texture) {
    if (texture >= 0) texture = texture_index[texture];
  };
  for (auto& material : scene.materials) {
    remap_texture(material.color_tex);
    remap_texture(material.emission_tex);
  }
  for (auto& environment : scene.environments) remap_texture(environment.emission_tex);

  // Files are checked one by one as they load; their sum is checked too.
  auto total = 0.0;
  for (auto i = 0; i < (int)scene.shapes.size(); i++) {
    auto error = std::string{};
    if (!load_shape(shape_paths[i], scene.shapes[i], error))
      return json_fail(loader, shape_labels[i] + ": " + error);
    total += shape_memory(scene.shapes[i]);
    if (!check_load_memory(loader.filename,
            "loading the shapes up to " + shape_labels[i], total, loader.error))
      return false;
  }
  for (auto i = 0; i < (int)scene.textures.size(); i++) {
    auto error = std::string{};
    if (!load_image(texture_paths[i], scene.textures[i], error))
      return json_fail(loader, texture_labels[i] + ": " + error);
    total += scene.textures[i].pixels.size() * sizeof(vec3f);
    if (!check_load_memory(loader.filename,
            "loading the shapes and textures up to " + texture_labels[i], total, loader.error))
      return false;
  }

  for (auto i = 0; i < (int)scene.materials.size(); i++) {
    auto& material = scene.materials[i];
    auto& info     = loader.material_infos[i];
    if (!info.has_type) material.type = infer_material_type(scene, i, info);
    auto label = element_label("material", scene.material_names[i], "", i);
    if (!finish_material(loader, label, material, info)) return false;
  }

  auto error = std::string{};
  if (!validate_scene(scene, error)) return json_fail(loader, error);
  return true;
}

bool load_scene(const std::string& filename, scene_data& scene, std::string& error,
    std::vector<std::string>* warnings) {
  scene       = {};
  auto loader = json_loader{filename, path_dirname(filename)};
  auto ok     = load_scene_json(loader, scene);
  if (warnings) {
    warnings->insert(warnings->end(), loader.warnings.begin(), loader.warnings.end());
  } else {
    for (auto& warning : loader.warnings) std::cerr << "warning: " << warning << "\n";
  }
  if (!ok) {
    error = loader.error;
    scene = {};
  }
  return ok;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// JSON SCENES: SAVING
// -----------------------------------------------------------------------------
namespace yocto {

// The double whose shortest decimal form is the float's shortest form, so
// that files read "0.1", not "0.10000000149011612", and still load back to
// the same float.
static double json_number(float value) {
  auto text   = format_float(value);
  auto number = 0.0;
  std::from_chars(text.data(), text.data() + text.size(), number);
  return (float)number == value ? number : (double)value;
}

static json json_array(const float* values, int count) {
  auto array = json::array();
  for (auto i = 0; i < count; i++) array.push_back(json_number(values[i]));
  return array;
}
static json json_vec3(const vec3f& v) { return json_array(&v.x, 3); }
static json json_frame(const frame3f& frame) {
  float values[12] = {frame.x.x, frame.x.y, frame.x.z, frame.y.x, frame.y.y, frame.y.z,
      frame.z.x, frame.z.y, frame.z.z, frame.o.x, frame.o.y, frame.o.z};
  return json_array(values, 12);
}

static std::string element_name(const std::vector<std::string>& names, size_t index) {
  return index < names.size() ? names[index] : std::string{};
}

// Unique file names under a directory, from element names made safe.
static std::vector<std::string> make_file_names(const std::vector<std::string>& names,
    size_t count, const std::string& kind, const std::string& extension) {
  auto files = std::vector<std::string>{};
  auto used  = std::unordered_set<std::string>{};
  for (size_t i = 0; i < count; i++) {
    auto stem = element_name(names, i);
    for (auto& c : stem)
      if (!std::isalnum((unsigned char)c) && c != '-' && c != '_' && c != '.') c = '_';
    if (stem.empty() || stem[0] == '.') stem = kind + std::to_string(i);
    auto unique = stem;
    for (auto k = 1; used.count(unique); k++) unique = stem + "-" + std::to_string(k);
    used.insert(unique);
    files.push_back(unique + extension);
  }
  return files;
}

static json make_scene_json(const scene_data& scene,
    const std::vector<std::string>& shape_files,
    const std::vector<std::string>& texture_files) {
  auto js           = json::object();
  auto named        = [](const std::vector<std::string>& names, size_t index) {
    auto element = json::object();
    auto name    = element_name(names, index);
    if (!name.empty()) element["name"] = name;
    return element;
  };
  js["asset"] = {{"version", "4.2"}, {"generator", "yocto-hair"}};
  if (!scene.copyright.empty()) js["asset"]["copyright"] = scene.copyright;
  auto& settings = scene.settings;
  if (settings.resolution != 0 || settings.samples != 0 || settings.bounces != 0)
    js["settings"] = {{"resolution", settings.resolution}, {"samples", settings.samples},
        {"bounces", settings.bounces}};

  auto cameras = json::array();
  for (size_t i = 0; i < scene.cameras.size(); i++) {
    auto& camera            = scene.cameras[i];
    auto  element           = named(scene.camera_names, i);
    element["frame"]        = json_frame(camera.frame);
    element["orthographic"] = camera.orthographic;
    element["lens"]         = json_number(camera.lens);
    element["film"]         = json_number(camera.film);
    element["aspect"]       = json_number(camera.aspect);
    element["focus"]        = json_number(camera.focus);
    element["aperture"]     = json_number(camera.aperture);
    cameras.push_back(element);
  }
  if (!cameras.empty()) js["cameras"] = cameras;

  auto environments = json::array();
  for (size_t i = 0; i < scene.environments.size(); i++) {
    auto& environment   = scene.environments[i];
    auto  element       = named(scene.environment_names, i);
    element["frame"]    = json_frame(environment.frame);
    element["emission"] = json_vec3(environment.emission);
    if (environment.emission_tex >= 0) element["emission_tex"] = environment.emission_tex;
    environments.push_back(element);
  }
  if (!environments.empty()) js["environments"] = environments;

  auto lights = json::array();
  for (auto& light : scene.distant_lights) {
    auto element         = json::object();
    element["direction"] = json_vec3(light.direction);
    element["emission"]  = json_vec3(light.emission);
    lights.push_back(element);
  }
  if (!lights.empty()) js["distant_lights"] = lights;

  auto textures = json::array();
  for (size_t i = 0; i < scene.textures.size(); i++) {
    auto element   = named(scene.texture_names, i);
    element["uri"] = "textures/" + texture_files[i];
    textures.push_back(element);
  }
  if (!textures.empty()) js["textures"] = textures;

  auto shapes = json::array();
  for (size_t i = 0; i < scene.shapes.size(); i++) {
    auto element   = named(scene.shape_names, i);
    element["uri"] = "shapes/" + shape_files[i];
    shapes.push_back(element);
  }
  if (!shapes.empty()) js["shapes"] = shapes;

  // Each type writes the keys it uses (the loader ignores the others).
  auto materials = json::array();
  for (size_t i = 0; i < scene.materials.size(); i++) {
    auto& material      = scene.materials[i];
    auto  element       = named(scene.material_names, i);
    element["type"]     = material_type_names[(int)material.type];
    element["emission"] = json_vec3(material.emission);
    if (material.emission_tex >= 0) element["emission_tex"] = material.emission_tex;
    if (material.type == material_type::hair) {
      // Optional keys when given, variation keys away from their defaults
      // (files without variation stay as they were), the others always.
      for (auto& parameter : hair_parameters) {
        auto write = parameter.has || parameter.group == hair_parameter_group::variation
                         ? is_hair_parameter_set(material.hair, parameter)
                         : true;
        if (!write) continue;
        auto value = get_hair_parameter(material.hair, parameter);
        element[parameter.name] = parameter.kind == hair_parameter_kind::number
                                      ? json(json_number(value.x))
                                      : json_vec3(value);
      }
    } else {
      element["color"] = json_vec3(material.color);
      if (material.color_tex >= 0) element["color_tex"] = material.color_tex;
      if (material.type == material_type::glossy) {
        element["roughness"] = json_number(material.roughness);
        element["ior"]       = json_number(material.ior);
      }
    }
    materials.push_back(element);
  }
  if (!materials.empty()) js["materials"] = materials;

  auto instances = json::array();
  for (size_t i = 0; i < scene.instances.size(); i++) {
    auto& instance      = scene.instances[i];
    auto  element       = named(scene.instance_names, i);
    element["frame"]    = json_frame(instance.frame);
    element["shape"]    = instance.shape;
    element["material"] = instance.material;
    instances.push_back(element);
  }
  if (!instances.empty()) js["instances"] = instances;
  return js;
}

bool save_scene(const std::string& filename, const scene_data& scene,
    std::string& error, bool ascii_shapes) {
  if (!validate_scene(scene, error)) {
    error = filename + ": cannot save scene: " + error;
    return false;
  }
  auto directory     = path_dirname(filename);
  auto shape_files   = make_file_names(scene.shape_names, scene.shapes.size(), "shape", ".ply");
  auto texture_files = make_file_names(
      scene.texture_names, scene.textures.size(), "texture", ".exr");

  // All or nothing: every file is written to its temporary first, and only
  // when all are complete are they renamed into place, the json last. A
  // failure (or a signal) before then leaves an existing scene untouched.
  auto files = std::vector<output_file>{};
  auto undo  = [&]() {
    discard_output_files(files);
    remove_output_directories();
    return false;
  };
  auto stage = [&](const std::string& path, const std::string& data) {
    files.emplace_back();
    return open_output_file(files.back(), path, error) &&
           write_output_file(files.back(), data.data(), data.size(), error) &&
           finish_output_file(files.back(), error);
  };
  auto data   = std::string{};
  auto status = (struct stat){};
  if (!directory.empty() && (stat(directory.c_str(), &status) != 0 || !S_ISDIR(status.st_mode))) {
    error = filename + ": no such directory " + directory;
    return false;
  }
  if (!scene.shapes.empty() && !make_output_directories(path_join(directory, "shapes"), error))
    return undo();
  for (size_t i = 0; i < scene.shapes.size(); i++) {
    auto path = path_join(directory, "shapes/" + shape_files[i]);
    if (!encode_shape(path, scene.shapes[i], data, error, ascii_shapes) || !stage(path, data))
      return undo();
  }
  if (!scene.textures.empty() &&
      !make_output_directories(path_join(directory, "textures"), error))
    return undo();
  for (size_t i = 0; i < scene.textures.size(); i++) {
    auto path = path_join(directory, "textures/" + texture_files[i]);
    if (!encode_image(path, scene.textures[i], data, error, 0) || !stage(path, data))
      return undo();
  }
  if (!stage(filename, make_scene_json(scene, shape_files, texture_files).dump(2) + "\n"))
    return undo();
  if (!commit_output_files(files, error)) return undo();
  keep_output_directories();
  return true;
}

}  // namespace yocto
