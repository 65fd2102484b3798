#pragma once
#include <string>
#include <string_view>

namespace cutsim::io {

/// Writes `bytes` to a temporary file beside `path` and renames it into
/// place, so a crash or a full disk never leaves a truncated file.
/// @throw OutputError naming the path and the system's reason.
void write_file_atomic(const std::string& path, std::string_view bytes);

/// Creates `dir` (and parents) if needed and checks that a file can be
/// created in it; leaves nothing behind.
/// @throw OutputError when the directory cannot be created or written.
void ensure_writable_directory(const std::string& dir);

}  // namespace cutsim::io
