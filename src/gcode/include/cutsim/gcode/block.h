#pragma once
// A block of an NC program as written: words with their columns, the
// 1-based physical line number and the original text. No geometry here.
#include <string>
#include <vector>

namespace cutsim::gcode {

struct Word {
  char letter = 0;    ///< upper case
  double value = 0;   ///< as written (program units)
  int column = 0;     ///< 1-based column of the letter
  int value_column = 0;  ///< 1-based column where the number starts
};

struct Block {
  int line = 0;          ///< 1-based physical line number
  std::string text;      ///< the line as written, without the line ending
  std::vector<Word> words;
  std::string message;   ///< text of an (MSG,...) comment, if any
};

/// G and M numbers compared as tenths, so G43.4 is 434 and G1 is 10.
inline int code_tenths(double v) { return static_cast<int>(v * 10.0 + (v >= 0 ? 0.5 : -0.5)); }

}  // namespace cutsim::gcode
