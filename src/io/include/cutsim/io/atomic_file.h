#pragma once
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace cutsim::io {

/// Writes `bytes` to a temporary file beside `path` and renames it into
/// place, so a crash or a full disk never leaves a truncated file.
/// @throw OutputError naming the path and the system's reason.
void write_file_atomic(const std::string& path, std::string_view bytes);

/// The same, written piece by piece: the bytes go to a temporary file that
/// commit() renames into place; destroyed uncommitted, it removes the
/// temporary file and leaves `path` as it was.
class AtomicFile {
public:
  /// @throw OutputError when the temporary file cannot be created.
  explicit AtomicFile(std::string path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  /// @throw OutputError naming the path and the system's reason.
  void write(const void* data, std::size_t n);
  void commit();

private:
  std::string path_, tmp_;
  int fd_ = -1;
};

/// An output directory made ready: `dir` (and its parents) created if
/// missing, and checked that a file can be created in it. The directories
/// it created are removed again when it is destroyed while they are still
/// empty, so a run that fails before writing its result leaves no trace.
class OutputDirectory {
public:
  /// @throw OutputError when the directory cannot be created or written.
  explicit OutputDirectory(const std::string& dir);
  ~OutputDirectory();
  OutputDirectory(const OutputDirectory&) = delete;
  OutputDirectory& operator=(const OutputDirectory&) = delete;

private:
  void remove_empty() noexcept;
  std::vector<std::string> created_;  // deepest first
};

}  // namespace cutsim::io
