#pragma once
// Parsing one line of RS274NGC / Fanuc G-code into a Block, evaluating
// parameters and expressions against the current parameter values.
#include <istream>
#include <string>
#include <string_view>

#include "cutsim/gcode/block.h"
#include "cutsim/gcode/line_source.h"
#include "cutsim/gcode/parameters.h"

namespace cutsim::gcode {

/// Parses `text` (line `line_no` of `file`) into `block`.
/// Words: a letter and a real value: a number (leading zero, sign and
/// decimal point optional, spaces allowed inside as RS274NGC does), a
/// parameter `#5`, `##1`, `#[1+2]`, `#<name>`, an expression `[...]` or a
/// unary function `sin[30]`. Parameter settings `#1=...` take effect after
/// the whole line has been read, as RS274NGC requires. `( )` and `;`
/// comments, `(MSG,...)`.
/// @throw ParseError (file:line:col) for malformed numbers, unknown
///        characters or functions, unclosed comments or brackets, division
///        by zero, out-of-domain functions, non-finite results, undefined
///        named parameters.
void parse_line(const std::string& file, int line_no, std::string_view text, Parameters& params,
                Dialect dialect, Block& block);

/// Reads blocks line by line without control flow (tests, simple tools).
/// Lines without words or O-words are skipped.
class BlockReader {
public:
  BlockReader(std::istream& in, std::string file_name, Dialect dialect = Dialect::rs274ngc);
  bool next(Block& block);
  static void parse_line(const std::string& file, int line_no, const std::string& text, Block& block);
  int lines_read() const { return src_.line_number(); }

private:
  LineSource src_;
  Parameters params_;
  Dialect dialect_;
};

}  // namespace cutsim::gcode
