// The block reader: words, columns, comments and malformed input.
#include <cstdlib>
#include <random>
#include <sstream>

#include "cutsim/core/error.h"
#include "cutsim/gcode/block_reader.h"
#include "helpers.h"

namespace cutsim::test {
namespace {

using gcode::Block;
using gcode::BlockReader;

Block parse(const std::string& line) {
  Block b;
  BlockReader::parse_line("t.nc", 7, line, b);
  return b;
}

SourceLocation error_at(const std::string& line) {
  try {
    parse(line);
  } catch (const ParseError& e) {
    return e.where();
  }
  ADD_FAILURE() << "no error for: " << line;
  return {};
}

TEST(BlockReader, WordsKeepValuesAndColumns) {
  const Block b = parse("n10 g1 x-.5 Y+2.25 z3. F100 (comment) ; tail");
  ASSERT_EQ(b.words.size(), 6u);
  EXPECT_EQ(b.words[0].letter, 'N');
  EXPECT_EQ(b.words[1].letter, 'G');
  EXPECT_DOUBLE_EQ(b.words[1].value, 1);
  EXPECT_EQ(b.words[2].letter, 'X');
  EXPECT_DOUBLE_EQ(b.words[2].value, -0.5);
  EXPECT_EQ(b.words[2].column, 8);
  EXPECT_DOUBLE_EQ(b.words[3].value, 2.25);
  EXPECT_DOUBLE_EQ(b.words[4].value, 3.0);
  EXPECT_EQ(b.words[5].column, 24);
  EXPECT_EQ(b.line, 7);
}

TEST(BlockReader, CommentsPercentAndCrlfAreSkipped) {
  std::istringstream in("%\r\n(only a comment)\r\n; also\r\n\r\nG0 X1\r\n%\r\n");
  BlockReader r(in, "t.nc");
  Block b;
  ASSERT_TRUE(r.next(b));
  EXPECT_EQ(b.line, 5);
  EXPECT_EQ(b.text, "G0 X1");
  EXPECT_FALSE(r.next(b));
  EXPECT_EQ(r.lines_read(), 6);
}

TEST(BlockReader, MessageCommentIsKept) {
  EXPECT_EQ(parse("G0 X0 (MSG,hello there)").message, "hello there");
}

TEST(BlockReader, MalformedNumberPointsAtTheSecondDecimalPoint) {
  const auto w = error_at("G1 X1.2.3 Y0");
  EXPECT_EQ(w.line, 7);
  EXPECT_EQ(w.column, 8);
}

TEST(BlockReader, UnclosedCommentPointsAtTheParenthesis) {
  EXPECT_EQ(error_at("G1 X1 (open").column, 7);
}

TEST(BlockReader, WordWithoutNumberIsAnError) {
  EXPECT_EQ(error_at("G1 X Y2").column, 4);
}

TEST(BlockReader, UnknownCharacterIsAnError) {
  EXPECT_EQ(error_at("G1 X1 $").column, 7);
  EXPECT_EQ(error_at("G1 X1 \x01").column, 7);
}

TEST(BlockReader, HugeNumberIsOutOfRange) {
  EXPECT_EQ(error_at("G1 X" + std::string(400, '9')).column, 5);
}

TEST(BlockReader, ErrorFormatShowsTheLineAndACaret) {
  try {
    parse("G1 X1.2.3");
    FAIL();
  } catch (const ParseError& e) {
    EXPECT_EQ(e.format(), "t.nc:7:8: error: malformed number: second decimal point\n  G1 X1.2.3\n         ^");
    EXPECT_EQ(e.code(), ExitCode::data);
  }
}

TEST(BlockReader, NumbersAreBitIdenticalToStrtod) {
  std::mt19937_64 rng(7);
  for (int i = 0; i < 20000; ++i) {
    const int int_digits = static_cast<int>(rng() % 6), frac_digits = static_cast<int>(rng() % 21);
    std::string num = (rng() % 2) ? "-" : "";
    for (int k = 0; k < int_digits; ++k) num += static_cast<char>('0' + rng() % 10);
    num += '.';
    for (int k = 0; k < frac_digits; ++k) num += static_cast<char>('0' + rng() % 10);
    if (int_digits == 0 && frac_digits == 0) num += '0';
    const Block b = parse("X" + num);
    ASSERT_EQ(b.words.size(), 1u);
    EXPECT_EQ(b.words[0].value, std::strtod(num.c_str(), nullptr)) << num;
  }
}

}  // namespace
}  // namespace cutsim::test
