// Programs cutsim must refuse: the error names the line and column.
#include "cutsim/core/error.h"
#include "cutsim/sim/simulate.h"
#include "helpers.h"

namespace cutsim::test {
namespace {

struct Expect {
  int line;
  int column;  // 0: any
  std::string message;
};

void expect_refused(const std::string& program, const Expect& e, gcode::Dialect d = gcode::Dialect::rs274ngc) {
  TempDir dir;
  const auto path = dir.write("p.nc", program);
  sim::ProgramOptions popt;
  popt.dialect = d;
  try {
    sim::check_program(path, popt, motion::InterpreterOptions{});
    ADD_FAILURE() << "accepted: " << program;
  } catch (const ParseError& err) {
    EXPECT_EQ(err.where().line, e.line) << err.format();
    if (e.column) {
      EXPECT_EQ(err.where().column, e.column) << err.format();
    }
    EXPECT_NE(err.message().find(e.message), std::string::npos) << err.format();
  }
}

TEST(ProgramErrors, DivisionByZero) { expect_refused("#1 = 0\nG0 X[1/#1]\n", {2, 7, "division by zero"}); }
TEST(ProgramErrors, UnclosedBracket) { expect_refused("G0 X[1+2\n", {1, 5, "unclosed '['"}); }
TEST(ProgramErrors, DeeplyNestedBrackets) {
  expect_refused("G0 X" + std::string(200, '[') + "1" + std::string(200, ']') + "\n", {1, 0, "nested too deeply"});
}
TEST(ProgramErrors, UndefinedNamedParameter) { expect_refused("G0 X#<nope>\n", {1, 5, "#<nope> is not defined"}); }
TEST(ProgramErrors, SqrtOfNegative) { expect_refused("G0 X[SQRT[-1]]\n", {1, 0, "SQRT of a negative"}); }
TEST(ProgramErrors, UnknownFunction) { expect_refused("G0 X[FOO[1]]\n", {1, 6, "expected a number"}); }
TEST(ProgramErrors, EndwhileWithoutWhile) { expect_refused("G0 X0\no1 endwhile\n", {2, 1, "endwhile without its while"}); }
TEST(ProgramErrors, WhileWithoutEndwhile) { expect_refused("o1 while [1]\nG0 X0\n", {1, 0, "the file ends inside o1 while"}); }
TEST(ProgramErrors, UndefinedSubroutine) { expect_refused("G0 X0\no7 call\n", {2, 1, "o7 is not defined"}); }
TEST(ProgramErrors, RunawayRecursion) {
  expect_refused("o1 sub\no1 call\no1 endsub\no1 call\n", {2, 1, "nested deeper than 64"});
}
TEST(ProgramErrors, ReturnOutsideSubroutine) { expect_refused("o1 return\n", {1, 1, "return outside a subroutine"}); }
TEST(ProgramErrors, G93FeedMoveWithoutF) {
  expect_refused("G0 X0\nG93 G1 X1 F1\nG1 X2\n", {3, 1, "G93 inverse time needs a positive F"});
}
TEST(ProgramErrors, G95WithoutSpindleSpeed) {
  expect_refused("G0 X0\nG95 G1 X1 F0.1\n", {2, 1, "no spindle speed"});
}
TEST(ProgramErrors, FanucCodesAreUnknownInRs274ngc) { expect_refused("G68.2 X0 Y0 Z0 I0 J0 K0\n", {1, 1, "unknown G code G68.2"}); }
TEST(ProgramErrors, RsCodesAreUnknownInFanuc) {
  expect_refused("G7 X1\n", {1, 1, "unknown G code G7"}, gcode::Dialect::fanuc);
}
TEST(ProgramErrors, FanucMissingSubprogram) {
  expect_refused("O1\nM98 P42\nM30\n", {2, 1, "O42 is not in this file"}, gcode::Dialect::fanuc);
}
TEST(ProgramErrors, FanucXAndUTogether) {
  expect_refused("G0 X1 U1\n", {1, 7, "both X and U"}, gcode::Dialect::fanuc);
}
TEST(ProgramErrors, ArcInTheWrongPlane) { expect_refused("G18 G0 X1 Z0\nG2 X0 Z1 I-1 J0 F1\n", {2, 14, "'J' is not in the arc plane"}); }
TEST(ProgramErrors, G53WithArc) { expect_refused("G0 X1\nG53 G2 X0 Y1 I-1 F1\n", {2, 1, "G53 needs G0 or G1"}); }
TEST(ProgramErrors, HomeReturnIsNamed) { expect_refused("G28 Z0\n", {1, 1, "return to home"}); }

TEST(ProgramBehaviour, BlockDeleteSkipsSlashLinesOnlyWhenOn) {
  TempDir dir;
  const auto path = dir.write("p.nc", "G0 X0\n/G0 X5\nG0 Y1\n");
  sim::ProgramOptions popt;
  int n = 0;
  sim::check_program(path, popt, {}, [&](const motion::Move&) { ++n; });
  EXPECT_EQ(n, 3);
  popt.block_delete = true;
  n = 0;
  sim::check_program(path, popt, {}, [&](const motion::Move& m) { ++n; EXPECT_NE(m.line, 2); });
  EXPECT_EQ(n, 2);
}

TEST(ProgramErrors, NulByteIsAnErrorAtItsColumn) {
  expect_refused(std::string("G0 X0\nG1 X1\0 F1\n", 17), {2, 6, "unexpected control"});
}

TEST(ProgramBehaviour, HundredKilobyteLineIsRead) {
  TempDir dir;
  const auto path = dir.write("p.nc", "G0 X0 (" + std::string(100 * 1024, 'a') + ") Y2\n");
  int n = 0;
  sim::check_program(path, {}, {}, [&](const motion::Move& m) {
    ++n;
    EXPECT_DOUBLE_EQ(m.end.xyz.y(), 2.0);
  });
  EXPECT_EQ(n, 1);
}

TEST(ProgramBehaviour, LongLineIsRefusedNotRead) {
  TempDir dir;
  const auto path = dir.write("p.nc", "G0 X0\n(" + std::string(2 << 20, 'a') + ")\n");
  try {
    sim::check_program(path, {}, {});
    FAIL();
  } catch (const ParseError& e) {
    EXPECT_EQ(e.where().line, 2);
    EXPECT_NE(e.message().find("longer than"), std::string::npos);
  }
}

}  // namespace
}  // namespace cutsim::test
