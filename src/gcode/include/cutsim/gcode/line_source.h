#pragma once
// Physical lines of a program, read in large chunks, with positions that can
// be returned to (loops, subroutines). Memory is bounded by the longest line.
#include <cstddef>
#include <istream>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace cutsim::gcode {

struct LinePosition {
  std::streamoff offset = 0;  ///< byte offset of the line's first character
  int line = 1;               ///< its 1-based line number
};

class LineSource {
public:
  /// `max_line_bytes`: a longer line is an error (ParseError at its line).
  LineSource(std::istream& in, std::string file, std::size_t max_line_bytes = 1 << 20);

  /// The next line without its line ending (LF or CR-LF); false at the end.
  /// The view is valid until the next call.
  bool next(std::string_view& line);
  /// 1-based number of the line last returned.
  int line_number() const { return line_no_; }
  /// Where the next line starts.
  LinePosition tell() const { return LinePosition{base_ + static_cast<std::streamoff>(pos_), line_no_ + 1}; }
  /// Continue reading at `p` (a position returned by tell()).
  void seek(const LinePosition& p);
  const std::string& file() const { return file_; }

private:
  bool fill();
  std::istream& in_;
  std::string file_;
  std::size_t max_line_;
  std::unique_ptr<char[]> buf_;  // not zero-filled: a reader is cheap to make
  std::size_t cap_ = 0;
  std::size_t pos_ = 0, end_ = 0;  // unread bytes are buf_[pos_, end_)
  std::streamoff base_ = 0;        // stream offset of buf_[0]
  bool eof_ = false;
  int line_no_ = 0;
  std::string long_line_;
};

}  // namespace cutsim::gcode
