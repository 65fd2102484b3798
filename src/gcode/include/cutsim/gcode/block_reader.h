#pragma once
// Streaming lexer for RS274/ISO programs: one block per physical line, read
// on demand, so memory does not grow with program length.
#include <istream>
#include <string>

#include "cutsim/gcode/block.h"

namespace cutsim::gcode {

/// Reads blocks from a stream.
/// Accepts: letter words with signed decimal numbers (leading zero and
/// decimal point optional), `( )` and `;` comments, `%` lines, N words,
/// spaces and tabs anywhere between words, CR-LF line endings, any case.
/// @throw ParseError (file:line:col) for a malformed number, an unknown
///        character, an unclosed comment or a word without a number.
class BlockReader {
public:
  BlockReader(std::istream& in, std::string file_name);

  /// Fills `block` with the next line that holds words; false at the end.
  /// Lines without words (blank, comment-only, `%`) are skipped.
  bool next(Block& block);

  /// Parses one line (exposed for tests and fuzzing).
  static void parse_line(const std::string& file, int line_no, const std::string& text,
                         Block& block);

  const std::string& file_name() const { return file_; }
  int lines_read() const { return line_no_; }

private:
  std::istream& in_;
  std::string file_;
  int line_no_ = 0;
  std::string line_;
};

}  // namespace cutsim::gcode
