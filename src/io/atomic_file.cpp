#include "cutsim/io/atomic_file.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <utility>
#include <fcntl.h>
#include <unistd.h>

#include "cutsim/core/error.h"

namespace cutsim::io {

namespace fs = std::filesystem;

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)), tmp_(path_ + ".tmp." + std::to_string(::getpid())) {
  fd_ = ::open(tmp_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) throw OutputError(path_, std::string("cannot create: ") + std::strerror(errno));
}

AtomicFile::~AtomicFile() {
  if (fd_ < 0) return;
  ::close(fd_);
  ::unlink(tmp_.c_str());
}

void AtomicFile::write(const void* data, std::size_t n) {
  const auto* p = static_cast<const char*>(data);
  std::size_t done = 0;
  while (done < n) {
    const ssize_t k = ::write(fd_, p + done, n - done);
    if (k < 0) {
      if (errno == EINTR) continue;
      throw OutputError(path_, std::string("cannot write: ") + std::strerror(errno));
    }
    done += static_cast<std::size_t>(k);
  }
}

void AtomicFile::commit() {
  const int fd = fd_;
  fd_ = -1;
  if (::fsync(fd) != 0) {
    const int e = errno;
    ::close(fd);
    ::unlink(tmp_.c_str());
    throw OutputError(path_, std::string("cannot write: ") + std::strerror(e));
  }
  if (::close(fd) != 0) {
    const int e = errno;
    ::unlink(tmp_.c_str());
    throw OutputError(path_, std::string("cannot write: ") + std::strerror(e));
  }
  if (std::rename(tmp_.c_str(), path_.c_str()) != 0) {
    const int e = errno;
    ::unlink(tmp_.c_str());
    throw OutputError(path_, std::string("cannot rename into place: ") + std::strerror(e));
  }
}

void write_file_atomic(const std::string& path, std::string_view bytes) {
  AtomicFile f(path);
  f.write(bytes.data(), bytes.size());
  f.commit();
}

OutputDirectory::OutputDirectory(const std::string& dir) {
  std::error_code ec;
  // The levels that do not exist yet, deepest first: these are ours.
  for (fs::path p = fs::absolute(dir, ec).lexically_normal(); !p.empty() && p != p.root_path(); p = p.parent_path()) {
    if (p.filename().empty()) continue;  // a trailing separator
    if (fs::exists(fs::symlink_status(p, ec))) break;
    created_.push_back(p.string());
  }
  try {
    fs::create_directories(dir, ec);
    if (ec) throw OutputError(dir, "cannot create output directory: " + ec.message());
    if (!fs::is_directory(dir, ec)) throw OutputError(dir, "output path is not a directory");
    const std::string probe = (fs::path(dir) / (".cutsim-probe." + std::to_string(::getpid()))).string();
    const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd < 0) throw OutputError(dir, std::string("cannot write to output directory: ") + std::strerror(errno));
    ::close(fd);
    ::unlink(probe.c_str());
  } catch (...) {
    remove_empty();
    throw;
  }
}

void OutputDirectory::remove_empty() noexcept {
  std::error_code ec;
  for (const std::string& d : created_)
    if (!fs::remove(d, ec)) break;  // not empty (the result is in it), or gone: keep the rest
}

OutputDirectory::~OutputDirectory() { remove_empty(); }

}  // namespace cutsim::io
