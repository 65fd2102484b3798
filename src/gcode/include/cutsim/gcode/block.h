#pragma once
// A block of an NC program: evaluated words with their columns, the 1-based
// physical line number and the original text. No geometry here.
#include <string>
#include <vector>

namespace cutsim::gcode {

enum class Dialect { rs274ngc, fanuc };

struct Word {
  char letter = 0;           ///< upper case
  double value = 0;          ///< evaluated, as written (program units)
  int column = 0;            ///< 1-based column of the letter
  int value_column = 0;      ///< 1-based column where the value starts
  bool integer_literal = false;  ///< a plain number written without '.'
};

/// O-word control (RS274NGC) or a Fanuc program number line.
enum class OKind {
  none, sub, endsub, call, ret, do_, while_, endwhile, if_, elseif, else_, endif,
  repeat, endrepeat, break_, continue_, program_number
};

struct OWord {
  OKind kind = OKind::none;
  std::string name;            ///< "100" or "name" (lower case)
  int column = 0;
  bool has_value = false;      ///< condition, repeat count or return value given
  double value = 0;
  std::vector<double> args;    ///< call arguments
};

struct Block {
  int line = 0;                ///< 1-based physical line number
  std::string text;            ///< the line as written, without the line ending
  std::vector<Word> words;
  std::string message;         ///< text of an (MSG,...) comment, if any
  OWord o;
  bool has_assignments = false;  ///< the line set parameters

  const Word* find(char letter) const {
    for (const Word& w : words)
      if (w.letter == letter) return &w;
    return nullptr;
  }
};

/// G and M numbers compared as tenths, so G43.4 is 434 and G1 is 10; a
/// value no code can have gives -1.
inline int code_tenths(double v) {
  if (!(v >= 0 && v < 1e6)) return -1;
  return static_cast<int>(v * 10.0 + 0.5);
}

}  // namespace cutsim::gcode
