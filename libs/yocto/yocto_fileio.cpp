//
// Implementation of Yocto/FileIO: see yocto_fileio.h.
//

#include "yocto_fileio.h"

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
#include <cstdlib>
#include <cstring>
#include <filesystem>

// -----------------------------------------------------------------------------
// MEMORY BUDGET
// -----------------------------------------------------------------------------
namespace yocto {

// The address space the process maps now (VmSize), from /proc/self/statm;
// 0 where that cannot be read. Nothing is allocated (no FILE buffer): this
// runs under a lowered ulimit -v too.
static double mapped_bytes() {
  auto descriptor = open("/proc/self/statm", O_RDONLY | O_CLOEXEC);
  if (descriptor < 0) return 0;
  char text[64] = {};
  auto size     = read(descriptor, text, sizeof(text) - 1);
  close(descriptor);
  auto pages = 0ll;
  if (size <= 0 || std::from_chars(text, text + size, pages).ec != std::errc{}) return 0;
  return (double)pages * (double)sysconf(_SC_PAGE_SIZE);
}

double default_memory_limit() {
  auto pages = sysconf(_SC_PHYS_PAGES), page_size = sysconf(_SC_PAGE_SIZE);
  auto limit = pages > 0 && page_size > 0 ? (double)pages * (double)page_size
                                          : 8.0 * (1 << 30);
  auto address_space = rlimit{};
  if (getrlimit(RLIMIT_AS, &address_space) == 0 &&
      address_space.rlim_cur != RLIM_INFINITY)
    limit = std::min(limit, (double)address_space.rlim_cur - mapped_bytes());
  return 0.75 * std::max(limit, 0.0);
}

std::string allocation_error(const std::string& filename, const std::string& what) {
  auto address_space = rlimit{};
  auto limited       = getrlimit(RLIMIT_AS, &address_space) == 0 &&
                 address_space.rlim_cur != RLIM_INFINITY;
  return filename + ": " + what + ": the memory it needs could not be allocated (" +
         (limited ? "the address-space limit, ulimit -v, is " +
                        std::to_string((long long)(address_space.rlim_cur >> 20)) + " MiB"
                  : std::string("the system refused it")) +
         "; --max-memory sets the budget of a load)";
}

bool check_load_memory(const std::string& filename, const std::string& what,
    double bytes, double max_memory, std::string& error) {
  if (bytes <= max_memory) return true;
  auto mebibytes = [](double bytes) {
    return std::to_string((long long)std::ceil(bytes / (1 << 20)));
  };
  error = filename + ": " + what + " needs " + mebibytes(bytes) +
          " MiB, over the memory limit of " + mebibytes(max_memory) +
          " MiB (--max-memory)";
  return false;
}

}  // namespace yocto

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
bool load_text(const std::string& filename, std::string& data, std::string& error,
    double max_memory) {
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
      !check_load_memory(filename, "reading the file", (double)size, max_memory, error))
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
    if (!check_load_memory(
            filename, "reading the file", (double)(data.size() + count), max_memory, error))
      return fail();
    data.append(buffer, (size_t)count);
  }
  ::close(fd);
  return true;
}

// Writes data through a temporary next to filename, checked and renamed.
bool save_text(const std::string& filename, const std::string& data, std::string& error,
    bool replace) {
  auto file = output_file{};
  if (!open_output_file(file, filename, error)) return false;
  if (!write_output_file(file, data.data(), data.size(), error)) {
    discard_output_file(file);
    return false;
  }
  return commit_output_file(file, error, replace);
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// VALUES IN FILES
// -----------------------------------------------------------------------------
namespace yocto {

std::string hex_string(uint64_t value) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%016llx", (unsigned long long)value);
  return buffer;
}

std::string format_float(float value) {
  char buffer[64];
  auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

}  // namespace yocto
