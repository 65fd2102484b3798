#pragma once
// The executable block stream of a program: lines parsed with parameters
// and expressions, RS274NGC O-word control flow (sub/call/return, while,
// do-while, if/elseif/else, repeat, break, continue) and Fanuc M98/M99
// subprograms carried out. Streams: only loop and subroutine positions are
// remembered, never the program.
#include <istream>
#include <string>
#include <unordered_map>
#include <vector>

#include "cutsim/gcode/block.h"
#include "cutsim/gcode/line_source.h"
#include "cutsim/gcode/parameters.h"

namespace cutsim::gcode {

struct ReaderOptions {
  Dialect dialect = Dialect::rs274ngc;
  bool block_delete = false;   ///< true: skip lines starting with '/'
  int max_call_depth = 64;
  std::size_t max_line_bytes = 1 << 20;
  /// Refuse to execute more lines than this (loops included); 0: no limit.
  long long max_lines_executed = 0;
};

class ProgramReader {
public:
  ProgramReader(std::istream& in, std::string file, ReaderOptions opt = {});

  /// The next block to execute (it has words; O-word lines are consumed
  /// here). False after M2/M30 or at the end of the file.
  /// @throw ParseError at the offending line and column.
  bool next(Block& block);

  Parameters& parameters() { return params_; }
  /// Highest physical line number read.
  int lines_read() const { return max_line_; }
  /// Lines executed, counting each pass through a loop or subroutine.
  long long lines_executed() const { return executed_; }

private:
  enum class FrameKind { call, m98, while_, do_, repeat, if_ };
  struct Frame {
    FrameKind kind;
    std::string name;
    LinePosition pos;     // call: return to; while: the while line; do/repeat/m98: body start
    long long remaining = 0;  // repeat / M98 L count
    int line = 0;         // where the construct started (for errors)
  };
  bool read_line(std::string_view& line);
  void parse(std::string_view line, Block& b);
  [[noreturn]] void fail(const Block& b, int column, const std::string& msg) const;
  // Skips lines until an O-word named `name` of one of `kinds`; parses
  // that line into `b` (evaluating it) and returns its kind.
  OKind skip_to(const std::string& name, std::initializer_list<OKind> kinds, const Block& from, Block& b);
  void handle_oword(Block& b);
  bool handle_fanuc_m98_m99(Block& b);
  LinePosition find_sub(const std::string& name, const Block& call);
  LinePosition find_program(const std::string& number, const Block& call);

  LineSource src_;
  std::string file_;
  ReaderOptions opt_;
  Parameters params_;
  std::vector<Frame> stack_;
  std::unordered_map<std::string, LinePosition> subs_;      // O-word subs: body start
  std::unordered_map<std::string, LinePosition> programs_;  // Fanuc O numbers: body start
  bool ended_ = false;
  int max_line_ = 0;
  long long executed_ = 0;
  Block scratch_;
};

}  // namespace cutsim::gcode
