// Modal interpretation: end points, arc centres, units, modes and errors.
#include <cmath>
#include <sstream>

#include "cutsim/core/error.h"
#include "cutsim/gcode/block_reader.h"
#include "cutsim/motion/interpreter.h"
#include "helpers.h"

namespace cutsim::test {
namespace {

using motion::MotionKind;
using motion::Move;

std::vector<Move> interpret(const std::string& program) {
  std::istringstream in(program);
  gcode::BlockReader reader(in, "t.nc");
  motion::Interpreter interp("t.nc");
  std::vector<Move> moves;
  gcode::Block b;
  while (reader.next(b)) interp.execute(b, moves);
  return moves;
}

SourceLocation error_of(const std::string& program) {
  try {
    interpret(program);
  } catch (const ParseError& e) {
    return e.where();
  }
  ADD_FAILURE() << "no error for: " << program;
  return {};
}

void expect_vec(const Vec3& a, const Vec3& b) {
  EXPECT_NEAR(a.x(), b.x(), 1e-9);
  EXPECT_NEAR(a.y(), b.y(), 1e-9);
  EXPECT_NEAR(a.z(), b.z(), 1e-9);
}

TEST(Interpreter, LinearMovesAbsoluteIncrementalAndInches) {
  const auto m = interpret("G21 G90 G0 X1 Y2 Z3\nG91 G1 X1 F100\nG20 G1 Y1\nG90 G21 G0 Z0\n");
  ASSERT_EQ(m.size(), 4u);
  expect_vec(m[0].end.xyz, Vec3(1, 2, 3));
  EXPECT_EQ(m[0].kind, MotionKind::rapid);
  expect_vec(m[1].end.xyz, Vec3(2, 2, 3));
  EXPECT_DOUBLE_EQ(m[1].feed_mm_per_min, 100);
  expect_vec(m[2].end.xyz, Vec3(2, 2 + 25.4, 3));
  EXPECT_DOUBLE_EQ(m[2].feed_mm_per_min, 100) << "a feed keeps its physical rate across G20";
  expect_vec(m[3].end.xyz, Vec3(2, 27.4, 0));
  EXPECT_EQ(m[1].line, 2);
  EXPECT_EQ(*m[1].text, "G91 G1 X1 F100");
}

TEST(Interpreter, G17ArcCentresIjkAndR) {
  const auto m = interpret("G17 G0 X0 Y0\nG2 X1 Y1 R1 F10\nG3 X0 Y0 I-1 J0\nG2 X2 Y0 R-1\n");
  ASSERT_EQ(m.size(), 4u);
  expect_vec(m[1].centre, Vec3(1, 0, 0));
  EXPECT_NEAR(m[1].arc_sweep_angle(), -kPi / 2, 1e-12);
  expect_vec(m[2].centre, Vec3(0, 1, 0));
  EXPECT_NEAR(m[2].arc_sweep_angle(), 3 * kPi / 2 - 2 * kPi + 2 * kPi, 1e-12);
  expect_vec(m[3].centre, Vec3(1, 0, 0));
  EXPECT_NEAR(std::fabs(m[3].arc_sweep_angle()), kPi, 1e-9);
}

TEST(Interpreter, G18AndG19ArcsTurnAboutTheirPlaneNormals) {
  // G18: positive (G3) rotation about +Y takes +X towards -Z.
  auto m = interpret("G18 G0 X1 Y0 Z0\nG3 X0 Z-1 I-1 K0 F10\n");
  ASSERT_EQ(m.size(), 2u);
  expect_vec(m[1].centre, Vec3(0, 0, 0));
  EXPECT_NEAR(m[1].arc_sweep_angle(), kPi / 2, 1e-12);
  expect_vec(m[1].point_at(0.5), Vec3(std::sqrt(0.5), 0, -std::sqrt(0.5)));
  // G19: positive rotation about +X takes +Y towards +Z.
  m = interpret("G19 G0 X0 Y1 Z0\nG3 Y0 Z1 J-1 K0 F10\n");
  expect_vec(m[1].point_at(0.5), Vec3(0, std::sqrt(0.5), std::sqrt(0.5)));
}

TEST(Interpreter, HelixAndFullCircle) {
  const auto m = interpret("G0 X1 Y0 Z0\nG2 X1 Y0 Z-1 I-1 J0 F10\n");
  ASSERT_EQ(m.size(), 2u);
  EXPECT_NEAR(m[1].arc_sweep_angle(), -2 * kPi, 1e-12);
  expect_vec(m[1].point_at(0.25), Vec3(0, -1, -0.25));
  expect_vec(m[1].point_at(1.0), Vec3(1, 0, -1));
}

TEST(Interpreter, ToolSpindleAndProgramEnd) {
  motion::Interpreter interp("t.nc");
  std::istringstream in("T3 M6\nS12000 M3\nM30\nG0 X1\n");
  gcode::BlockReader reader(in, "t.nc");
  gcode::Block b;
  std::vector<Move> moves;
  while (reader.next(b)) interp.execute(b, moves);
  EXPECT_EQ(interp.state().tool_in_spindle, 3);
  EXPECT_EQ(interp.state().spindle_dir, 1);
  EXPECT_DOUBLE_EQ(interp.state().spindle_rpm, 12000);
  EXPECT_TRUE(moves.empty()) << "blocks after M30 do not move";
  ASSERT_EQ(interp.warnings().size(), 1u);
  EXPECT_EQ(interp.warnings()[0].line, 4);
}

TEST(Interpreter, UnknownCodesAreErrorsAtTheirColumn) {
  auto w = error_of("G0 X0\nG1 X1 G12 F1\n");
  EXPECT_EQ(w.line, 2);
  EXPECT_EQ(w.column, 7);
  w = error_of("M77\n");
  EXPECT_EQ(w.column, 1);
  EXPECT_EQ(error_of("G0 Q1\n").column, 4);
}

TEST(Interpreter, ModalGroupConflictIsAnError) {
  const auto w = error_of("G0 G1 X1 F1\n");
  EXPECT_EQ(w.column, 4);
  EXPECT_EQ(error_of("G90 G91 X1\n").column, 5);
}

TEST(Interpreter, UnsupportedCompensationAndCyclesNameTheCode) {
  try {
    interpret("G41 D1\n");
    FAIL();
  } catch (const ParseError& e) {
    EXPECT_NE(e.message().find("cutter radius compensation"), std::string::npos);
  }
  try {
    interpret("G81 X0 Y0 Z-1 R1 F10\n");
    FAIL();
  } catch (const ParseError& e) {
    EXPECT_NE(e.message().find("canned cycles"), std::string::npos);
  }
}

TEST(Interpreter, ArcRadiusShorterThanHalfChordIsAnError) {
  const auto w = error_of("G0 X0 Y0\nG2 X4 Y0 R1.5 F10\n");
  EXPECT_EQ(w.line, 2);
  EXPECT_EQ(w.column, 10);
}

TEST(Interpreter, ArcEndOffItsCircleIsAnErrorBeyondLinuxCncTolerance) {
  // Start radius 1, end radius 1.01: off by 0.01 mm (> 0.00127 and > 0.1 %).
  EXPECT_EQ(error_of("G0 X1 Y0\nG3 X0 Y1.01 I-1 J0 F10\n").line, 2);
  // Off by 0.0005 mm: within tolerance, accepted.
  EXPECT_EQ(interpret("G0 X1 Y0\nG3 X0 Y1.0005 I-1 J0 F10\n").size(), 2u);
}

TEST(Interpreter, FeedMoveWithoutFeedIsAnError) {
  EXPECT_EQ(error_of("G1 X1\n").line, 1);
}

TEST(Interpreter, AxisWordsWithoutMotionModeIsAnError) {
  EXPECT_EQ(error_of("X1\n").column, 1);
}

}  // namespace
}  // namespace cutsim::test
