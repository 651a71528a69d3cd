//
// # Yocto/FileIO: files, outputs and the memory budget of a load
//
// What every loader and saver shares: whole-file reads and writes, path
// helpers, outputs written to a temporary name and renamed when complete (so
// a failed or interrupted save leaves nothing behind), and the check of the
// sizes read from a file against the memory a load may use. The budget is a
// parameter of each load (default_memory_limit() unless the caller gives
// one), never a global. Plain C++ and POSIX: no image, json or zlib code.
//

#ifndef YOCTO_FILEIO_H_
#define YOCTO_FILEIO_H_

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

// -----------------------------------------------------------------------------
// MEMORY BUDGET
// -----------------------------------------------------------------------------
namespace yocto {

// The memory one load may ask for, in bytes, when the caller sets none: 3/4
// of physical memory, or of what the address-space limit (ulimit -v) leaves
// beside the address space the process already maps (its libraries) when
// that is lower. yscene passes --max-memory instead.
double default_memory_limit();

// The message for an allocation that failed (std::bad_alloc) while loading
// or building `what` of `filename`: the system, or ulimit -v, gave less than
// the budget let the load ask for. "FILENAME: WHAT: the memory it needs
// could not be allocated (...)", naming the address-space limit if any.
std::string allocation_error(const std::string& filename, const std::string& what);

// Sizes read from a file (image pixels, element counts, inflated text,
// generated geometry) are checked against the load's limit before anything
// is allocated, so a tiny file claiming a huge size fails with a message
// naming the file instead of exhausting memory. Checks that `what` in
// `filename` needing `bytes` fits `max_memory`; otherwise sets error to
// "FILENAME: WHAT needs N MiB, over the memory limit of M MiB (--max-memory)"
// and returns false. Bytes are a double so that products of untrusted counts
// cannot overflow.
bool check_load_memory(const std::string& filename, const std::string& what,
    double bytes, double max_memory, std::string& error);

}  // namespace yocto

// -----------------------------------------------------------------------------
// FILE HELPERS
// -----------------------------------------------------------------------------
namespace yocto {

// Checks that filename names a regular file and gives its size: a
// directory, a device (/dev/zero reads forever) or a fifo (blocks) is refused
// with a message naming it. Every loader checks its inputs with this first.
bool check_input_file(const std::string& filename, size_t& size, std::string& error);

// Writes a file through a temporary in the same directory, then renames
// (with replace false, an existing file is an error, never overwritten).
// The text is written byte for byte, so binary data works too.
bool save_text(const std::string& filename, const std::string& text, std::string& error,
    bool replace = true);
// Reads a whole regular file, its size checked against max_memory first.
bool load_text(const std::string& filename, std::string& text, std::string& error,
    double max_memory = default_memory_limit());

// Path helpers: directory of a path (with trailing separator or empty),
// extension (with dot, lower case), and join.
std::string path_dirname(const std::string& filename);
std::string path_extension(const std::string& filename);
std::string path_join(const std::string& directory, const std::string& filename);

// An output being written: a temporary next to its final name, created
// exclusively under an unpredictable name (never an existing file or a
// link planted there), filled, checked and renamed into place. Until then
// it is listed for remove_pending_outputs, so no exit path leaves it.
struct output_file {
  std::string filename  = "";  // the final name
  std::string temporary = "";  // where the bytes go until the rename
  int         descriptor = -1;
  size_t      written    = 0;
};

// Creates the temporary of `filename` (same folder and extension).
bool open_output_file(output_file& file, const std::string& filename, std::string& error);
// Writes all of `data` (short writes are continued, failures reported).
bool write_output_file(output_file& file, const void* data, size_t size, std::string& error);
// Flushes to disk and checks the size on disk against the bytes written:
// a full disk or a file-size limit fails here, not after the rename.
bool finish_output_file(output_file& file, std::string& error);
// Finishes the files and renames them into place as one step: signals wait
// until all are renamed, and if a rename fails the files already replaced
// are restored from backups. With replace false, an existing file is never
// overwritten (the commit fails instead). On failure nothing is left.
bool commit_output_files(std::vector<output_file>& files, std::string& error,
    bool replace = true);
bool commit_output_file(output_file& file, std::string& error, bool replace = true);
// Removes the temporaries of unfinished or failed outputs.
void discard_output_files(std::vector<output_file>& files);
void discard_output_file(output_file& file);

// Checks up front that `filename` can be written: its folder exists and
// takes a new file, the name is not a folder, and the disk has `bytes` free.
bool check_output_file(const std::string& filename, double bytes, std::string& error);

// A folder made for outputs: listed for remove_pending_outputs until
// keep_output_directories, so a failed or interrupted command removes the
// folders it created (only if empty; never one that existed).
bool make_output_directories(const std::string& directory, std::string& error);
void keep_output_directories();
void remove_output_directories();

// Removes every pending temporary and every folder listed above. Uses only
// unlink and rmdir, so signal handlers may call it.
void remove_pending_outputs();

}  // namespace yocto

// -----------------------------------------------------------------------------
// VALUES IN FILES
// -----------------------------------------------------------------------------
namespace yocto {

// A 64-bit value as 16 lower-case hex digits (part checksums, scene fingerprints).
std::string hex_string(uint64_t value);

// Shortest decimal form of a float that reads back to the same float.
std::string format_float(float value);

inline constexpr bool host_little_endian = __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__;

// Appends a little-endian binary value (binary PLY, PFM).
template <typename T>
inline void append_raw(std::string& buffer, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  if (!host_little_endian) std::reverse(bytes, bytes + sizeof(T));
  buffer.append(bytes, sizeof(T));
}

}  // namespace yocto

#endif
