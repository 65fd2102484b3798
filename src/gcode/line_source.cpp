#include "cutsim/gcode/line_source.h"

#include <cstring>

#include "cutsim/core/error.h"

namespace cutsim::gcode {

namespace {
constexpr std::size_t kChunk = 256 << 10;
}

LineSource::LineSource(std::istream& in, std::string file, std::size_t max_line_bytes)
    : in_(in), file_(std::move(file)), max_line_(max_line_bytes) {}

bool LineSource::fill() {
  if (eof_) return false;
  // Keep the unread tail, read more behind it.
  if (pos_ > 0) {
    std::memmove(buf_.get(), buf_.get() + pos_, end_ - pos_);
    base_ += static_cast<std::streamoff>(pos_);
    end_ -= pos_;
    pos_ = 0;
  }
  if (end_ + kChunk > cap_) {
    const std::size_t cap = std::max(end_ + kChunk, 2 * cap_);
    std::unique_ptr<char[]> bigger(new char[cap]);
    if (end_) std::memcpy(bigger.get(), buf_.get(), end_);
    buf_ = std::move(bigger);
    cap_ = cap;
  }
  in_.read(buf_.get() + end_, static_cast<std::streamsize>(kChunk));
  const std::streamsize got = in_.gcount();
  if (in_.bad()) throw InputError(file_, "read error");
  if (got <= 0) {
    eof_ = true;
    return false;
  }
  end_ += static_cast<std::size_t>(got);
  if (got < static_cast<std::streamsize>(kChunk)) eof_ = true;
  return true;
}

bool LineSource::next(std::string_view& line) {
  std::size_t scan = pos_;
  for (;;) {
    const void* nl = end_ > scan ? std::memchr(buf_.get() + scan, '\n', end_ - scan) : nullptr;
    if (nl) {
      const std::size_t e = static_cast<const char*>(nl) - buf_.get();
      std::size_t len = e - pos_;
      ++line_no_;
      if (len > max_line_)
        throw ParseError(SourceLocation{file_, line_no_, 1, {}},
                         "line is longer than " + std::to_string(max_line_) + " bytes");
      if (len > 0 && buf_[pos_ + len - 1] == '\r') --len;
      line = std::string_view(buf_.get() + pos_, len);
      pos_ = e + 1;
      return true;
    }
    if (end_ - pos_ > max_line_)
      throw ParseError(SourceLocation{file_, line_no_ + 1, 1, {}},
                       "line is longer than " + std::to_string(max_line_) + " bytes");
    const std::size_t scanned = end_ - pos_;
    if (!fill()) {
      if (pos_ == end_) return false;
      // Last line without a newline.
      std::size_t len = end_ - pos_;
      ++line_no_;
      if (len > 0 && buf_[pos_ + len - 1] == '\r') --len;
      line = std::string_view(buf_.get() + pos_, len);
      pos_ = end_;
      return true;
    }
    scan = pos_ + scanned;
  }
}

void LineSource::seek(const LinePosition& p) {
  if (p.offset >= base_ && p.offset <= base_ + static_cast<std::streamoff>(end_)) {
    pos_ = static_cast<std::size_t>(p.offset - base_);
  } else {
    in_.clear();
    in_.seekg(p.offset);
    if (!in_) throw InputError(file_, "cannot seek in the program (loops and subroutines need a seekable file)");
    base_ = p.offset;
    pos_ = end_ = 0;
    eof_ = false;
  }
  line_no_ = p.line - 1;
}

}  // namespace cutsim::gcode
