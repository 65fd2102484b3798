#include "cutsim/motion/interpreter.h"

#include <cmath>
#include <optional>

#include "cutsim/core/error.h"

namespace cutsim::motion {

namespace {

constexpr double kMmPerInch = 25.4;
using gcode::Dialect;

struct Ctx {
  const std::string& file;
  const gcode::Block& block;
  [[noreturn]] void fail(int column, const std::string& msg) const {
    throw ParseError(SourceLocation{file, block.line, column, block.text}, msg);
  }
};

// Modal groups (RS274NGC numbering; 16 is Fanuc's G68.2/G69).
enum Group { kNone = -1, kNonModal = 0, kMotion = 1, kPlane = 2, kDistance = 3, kArcDistance = 4,
             kFeedMode = 5, kUnits = 6, kCutterComp = 7, kToolLength = 8, kCoordSys = 12,
             kPathMode = 13, kLatheDiameter = 15, kTilt = 16, kGroups = 17 };

Group g_group(int t, Dialect d) {
  const bool fanuc = d == Dialect::fanuc;
  switch (t) {
    case 0: case 10: case 20: case 30: case 800: return kMotion;
    case 170: case 180: case 190: return kPlane;
    case 900: case 910: return kDistance;
    case 901: case 911: return fanuc ? kNone : kArcDistance;
    case 930: case 940: case 950: return kFeedMode;
    case 200: case 210: return kUnits;
    case 400: return kCutterComp;
    case 430: case 490: return kToolLength;
    case 434: case 435: return fanuc ? kToolLength : kNone;
    case 540: case 550: case 560: case 570: case 580: case 590: return kCoordSys;
    case 591: case 592: case 593: return fanuc ? kNone : kCoordSys;
    case 610: case 640: return kPathMode;
    case 70: case 80: return fanuc ? kNone : kLatheDiameter;
    case 682: case 690: return fanuc ? kTilt : kNone;
    case 40: case 100: case 530: return kNonModal;
    case 531: return fanuc ? kNonModal : kNone;
    default: return kNone;
  }
}

enum MGroup { kMNone = -1, kStopping = 4, kToolChange = 6, kSpindle = 7, kCoolant = 8, kMGroups = 10 };

MGroup m_group(int t) {
  switch (t) {
    case 0: case 10: case 20: case 300: return kStopping;
    case 60: return kToolChange;
    case 30: case 40: case 50: return kSpindle;
    case 70: case 80: case 90: return kCoolant;
    default: return kMNone;
  }
}

std::string code_text(char letter, double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%c%g", letter, v);
  return buf;
}

// Fanuc ZXZ Euler angles (degrees) of G68.2 I J K.
Eigen::Matrix3d euler_zxz(double a, double b, double c) {
  return (Eigen::AngleAxisd(deg_to_rad(a), Vec3::UnitZ()) * Eigen::AngleAxisd(deg_to_rad(b), Vec3::UnitX()) *
          Eigen::AngleAxisd(deg_to_rad(c), Vec3::UnitZ())).toRotationMatrix();
}

}  // namespace

Interpreter::Interpreter(std::string file_name, InterpreterOptions options)
    : file_(std::move(file_name)), opt_(options), pos_(options.initial) {}

Vec3 Interpreter::to_program(const Vec3& machine) const {
  const Vec3 work = machine - opt_.work_offsets[static_cast<std::size_t>(state_.coord_system)].xyz;
  return state_.tilted ? Vec3(state_.tilt.inverse() * work) : work;
}

Vec3 Interpreter::to_machine(const Vec3& program) const {
  const Vec3 work = state_.tilted ? Vec3(state_.tilt * program) : program;
  return work + opt_.work_offsets[static_cast<std::size_t>(state_.coord_system)].xyz;
}

void Interpreter::execute(const gcode::Block& block, std::vector<Move>& out) {
  const Ctx ctx{file_, block};
  const bool fanuc = opt_.dialect == Dialect::fanuc;
  if (state_.ended) {
    warnings_.push_back({block.line, 1, "block after M2/M30 is ignored"});
    return;
  }

  std::optional<int> g_by_group[kGroups];
  int g_col[kGroups] = {};
  std::optional<int> m_by_group[kMGroups];
  const gcode::Word* w_by_letter[26] = {};

  for (const gcode::Word& w : block.words) {
    const char L = w.letter;
    if (L == 'G') {
      const int t = gcode::code_tenths(w.value);
      const Group g = g_group(t, opt_.dialect);
      if (g == kNone) {
        if (t == 410 || t == 420 || t == 411 || t == 421)
          ctx.fail(w.column, code_text('G', w.value) + ": cutter radius compensation is not supported");
        if (t >= 730 && t <= 890)
          ctx.fail(w.column, code_text('G', w.value) + ": canned cycles are not supported");
        if (t == 280 || t == 300 || t == 281 || t == 301)
          ctx.fail(w.column, code_text('G', w.value) + ": return to home needs the machine's home position, not supported");
        if (t == 920 || t == 921 || t == 922 || t == 923)
          ctx.fail(w.column, code_text('G', w.value) + ": G92 offsets are not supported; use G10 L2 / G54-G59");
        ctx.fail(w.column, "unknown G code " + code_text('G', w.value) +
                               (fanuc ? " (dialect fanuc)" : " (dialect rs274ngc)"));
      }
      if (g_by_group[g])
        ctx.fail(w.column, code_text('G', w.value) + " conflicts with " + code_text('G', *g_by_group[g] / 10.0) +
                               " in the same modal group");
      g_by_group[g] = t;
      g_col[g] = w.column;
      continue;
    }
    if (L == 'M') {
      const int t = gcode::code_tenths(w.value);
      const MGroup g = m_group(t);
      if (g == kMNone) ctx.fail(w.column, "unknown M code " + code_text('M', w.value));
      if (m_by_group[g])
        ctx.fail(w.column, code_text('M', w.value) + " conflicts with " + code_text('M', *m_by_group[g] / 10.0) +
                               " in the same modal group");
      m_by_group[g] = t;
      continue;
    }
    if (L == 'N') {
      if (&w != &block.words.front()) ctx.fail(w.column, "N word must come first in the block");
      continue;
    }
    const int li = L - 'A';
    if (w_by_letter[li]) ctx.fail(w.column, std::string("word '") + L + "' appears twice in the block");
    static const char kKnown[] = "XYZABCIJKRFSPTHDL";
    bool known = false;
    for (const char* k = kKnown; *k; ++k) known |= (*k == L);
    if (fanuc && (L == 'U' || L == 'V' || L == 'W')) known = true;
    if (!known) ctx.fail(w.column, std::string("unknown word '") + L + "'");
    w_by_letter[li] = &w;
  }
  auto word = [&](char L) { return w_by_letter[L - 'A']; };

  // Units first: they apply to every length on the line.
  if (g_by_group[kUnits]) state_.inches = (*g_by_group[kUnits] == 200);
  const double unit = state_.inches ? kMmPerInch : 1.0;
  // Fanuc reads a length written without a decimal point in the least input
  // increment (0.001 mm, 0.0001 in, 0.001 deg).
  auto length = [&](const gcode::Word& w) {
    double v = w.value;
    if (fanuc && w.integer_literal) v *= state_.inches ? 0.0001 : 0.001;
    return v * unit;
  };
  auto angle_deg = [&](const gcode::Word& w) {
    return (fanuc && w.integer_literal) ? w.value * 0.001 : w.value;
  };

  // RS274NGC order of execution: feed mode, feed, spindle, tool, M6,
  // offsets (G10), plane, units, diameter mode, tool length, coordinate
  // system, path mode, distance mode, tilt, motion, stop.
  if (g_by_group[kFeedMode]) {
    const int t = *g_by_group[kFeedMode];
    state_.feed_mode = t == 930 ? FeedMode::inverse_time : t == 950 ? FeedMode::per_revolution : FeedMode::per_minute;
  }
  const gcode::Word* f = word('F');
  if (f) {
    if (f->value < 0) ctx.fail(f->value_column, "negative feed rate");
    state_.feed = f->value * unit;
  }
  if (const gcode::Word* s = word('S')) {
    if (s->value < 0) ctx.fail(s->value_column, "negative spindle speed");
    state_.spindle_rpm = s->value;
  }
  if (const gcode::Word* t = word('T')) {
    if (t->value < 0 || t->value != std::floor(t->value) || t->value > 999999)
      ctx.fail(t->value_column, "tool number must be an integer from 0 to 999999");
    state_.tool_selected = static_cast<int>(t->value);
  }
  if (m_by_group[kSpindle]) {
    const int m = *m_by_group[kSpindle];
    state_.spindle_dir = m == 30 ? 1 : m == 40 ? -1 : 0;
  }
  if (m_by_group[kToolChange]) state_.tool_in_spindle = state_.tool_selected;

  const std::optional<int> nonmodal = g_by_group[kNonModal];
  const bool g10 = nonmodal && *nonmodal == 100;
  const bool g53 = nonmodal && *nonmodal == 530;
  const bool dwell = nonmodal && *nonmodal == 40;
  const bool g531 = nonmodal && *nonmodal == 531;

  if (g10) {
    const gcode::Word* l = word('L');
    const gcode::Word* p = word('P');
    if (!l || (l->value != 2 && l->value != 20)) ctx.fail(g_col[kNonModal], "G10 supports L2 and L20 (work offsets)");
    if (!p || p->value < 0 || p->value > 9 || p->value != std::floor(p->value))
      ctx.fail(p ? p->value_column : g_col[kNonModal], "G10 needs P0 to P9 (P0: the active system)");
    const int idx = p->value == 0 ? state_.coord_system : static_cast<int>(p->value) - 1;
    AxisValues& off = opt_.work_offsets[static_cast<std::size_t>(idx)];
    for (int a = 0; a < 3; ++a)
      if (const gcode::Word* w = word("XYZ"[a])) {
        const double v = length(*w);
        off.xyz[a] = l->value == 2 ? v : pos_.xyz[a] - v;
      }
    for (int a = 0; a < 3; ++a)
      if (const gcode::Word* w = word("ABC"[a])) {
        const double v = deg_to_rad(w->value);
        off.abc[a] = l->value == 2 ? v : pos_.abc[a] - v;
      }
  }

  if (g_by_group[kPlane]) {
    const int t = *g_by_group[kPlane];
    state_.plane = t / 10;
    state_.plane_normal = t == 170 ? Vec3::UnitZ() : t == 180 ? Vec3::UnitY() : Vec3::UnitX();
  }
  if (g_by_group[kLatheDiameter]) state_.diameter_mode = (*g_by_group[kLatheDiameter] == 70);
  if (g_by_group[kToolLength]) {
    const int t = *g_by_group[kToolLength];
    if (t == 490) {
      state_.length_offset_h = -1;
      state_.tcp = false;
    } else {
      const gcode::Word* h = word('H');
      int hv = state_.tool_in_spindle;
      if (h) {
        if (h->value < 0 || h->value != std::floor(h->value) || h->value > 999999)
          ctx.fail(h->value_column, "H must be an integer from 0 to 999999");
        hv = static_cast<int>(h->value);
      }
      state_.length_offset_h = hv;
      state_.tcp = (t == 434 || t == 435);
      if (hv != state_.tool_in_spindle)
        warnings_.push_back({block.line, g_col[kToolLength],
                             "tool length offset H" + std::to_string(hv) + " with T" +
                                 std::to_string(state_.tool_in_spindle) + " in the spindle (cutsim positions the tool tip)"});
    }
  }
  if (g_by_group[kCoordSys]) {
    const int t = *g_by_group[kCoordSys];
    state_.coord_system = t % 10 == 0 ? (t - 540) / 10 : 6 + (t % 10) - 1;
  }
  if (g_by_group[kDistance]) state_.absolute = (*g_by_group[kDistance] == 900);
  if (g_by_group[kArcDistance]) state_.arc_absolute = (*g_by_group[kArcDistance] == 901);

  if (g_by_group[kTilt]) {
    if (*g_by_group[kTilt] == 690) {
      state_.tilted = false;
      state_.tilt = Pose::Identity();
      state_.tool_axis_control = false;
    } else {
      // G68.2 X Y Z (origin, work coordinates) I J K (ZXZ Euler angles, deg).
      if (const gcode::Word* p = word('P'); p && p->value != 0)
        ctx.fail(p->column, "G68.2 supports P0 (Euler angles) only");
      Vec3 origin = Vec3::Zero();
      for (int a = 0; a < 3; ++a)
        if (const gcode::Word* w = word("XYZ"[a])) origin[a] = length(*w);
      double e[3] = {0, 0, 0};
      for (int a = 0; a < 3; ++a)
        if (const gcode::Word* w = word("IJK"[a])) e[a] = w->value;
      state_.tilt = Pose::Identity();
      state_.tilt.linear() = euler_zxz(e[0], e[1], e[2]);
      state_.tilt.translation() = origin;
      state_.tilted = true;
      state_.tool_axis_control = false;
    }
  }
  if (g531) {
    if (!state_.tilted) ctx.fail(g_col[kNonModal], "G53.1 without an active G68.2");
    state_.tool_axis_control = true;
  }

  if (dwell) {
    const gcode::Word* p = word('P');
    const gcode::Word* x = fanuc ? word('X') : nullptr;
    const gcode::Word* u = fanuc ? word('U') : nullptr;
    if (!p && !x && !u) ctx.fail(g_col[kNonModal], fanuc ? "G4 needs P (ms) or X/U (s)" : "G4 needs a P word (seconds)");
    if (p && p->value < 0) ctx.fail(p->value_column, "negative dwell");
  }

  if (g_by_group[kMotion]) {
    const int t = *g_by_group[kMotion];
    if (t == 800) {
      state_.motion_set = false;
    } else {
      state_.motion = t == 0 ? MotionKind::rapid : t == 10 ? MotionKind::linear
                    : t == 20 ? MotionKind::arc_cw : MotionKind::arc_ccw;
      state_.motion_set = true;
    }
  }

  // Axis words of this block (G10 and G68.2 and a Fanuc dwell use them).
  const bool axis_words_taken = g10 || g_by_group[kTilt].has_value() || (dwell && fanuc);
  static const char kAxes[] = "XYZABC";
  const gcode::Word* axis[6] = {};
  const gcode::Word* inc[3] = {};  // Fanuc U V W
  bool has_axis = false;
  if (!axis_words_taken) {
    for (int a = 0; a < 6; ++a) has_axis |= (axis[a] = word(kAxes[a])) != nullptr;
    if (fanuc)
      for (int a = 0; a < 3; ++a)
        if ((inc[a] = word("UVW"[a]))) {
          if (axis[a]) ctx.fail(inc[a]->column, std::string("both ") + kAxes[a] + " and " + "UVW"[a] + " in one block");
          has_axis = true;
        }
  }
  const gcode::Word* ijk[3] = {word('I'), word('J'), word('K')};
  const gcode::Word* r_word = word('R');
  const bool has_arc_words = !axis_words_taken && (ijk[0] || ijk[1] || ijk[2] || r_word);

  if (has_axis) {
    if (!state_.motion_set) {
      for (int a = 0; a < 6; ++a)
        if (axis[a]) ctx.fail(axis[a]->column, "axis words without an active motion mode (G0, G1, G2 or G3)");
      for (int a = 0; a < 3; ++a)
        if (inc[a]) ctx.fail(inc[a]->column, "axis words without an active motion mode (G0, G1, G2 or G3)");
    }
    if (g53 && (state_.motion != MotionKind::rapid && state_.motion != MotionKind::linear))
      ctx.fail(g_col[kNonModal], "G53 needs G0 or G1");
    Move m;
    m.line = block.line;
    m.text = std::make_shared<const std::string>(block.text);
    m.kind = state_.motion;
    m.start = pos_;
    m.tool = state_.tool_in_spindle;
    m.spindle_rpm = state_.spindle_rpm;
    m.normal = state_.plane_normal;
    m.tcp = state_.tcp;
    if (state_.tool_axis_control) m.tool_axis = state_.tilt.linear() * Vec3::UnitZ();

    // Targets in program coordinates (or machine coordinates with G53).
    const Vec3 cur = g53 ? pos_.xyz : to_program(pos_.xyz);
    Vec3 target = cur;
    for (int a = 0; a < 3; ++a) {
      double scale = (a == 0 && state_.diameter_mode) ? 0.5 : 1.0;
      if (axis[a]) {
        const double v = length(*axis[a]) * scale;
        target[a] = (state_.absolute || g53) ? v : cur[a] + v;
      } else if (inc[a]) {
        target[a] = cur[a] + length(*inc[a]) * scale;
      }
    }
    AxisValues end = pos_;
    end.xyz = g53 ? target : to_machine(target);
    const AxisValues& off = opt_.work_offsets[static_cast<std::size_t>(state_.coord_system)];
    for (int a = 0; a < 3; ++a)
      if (axis[3 + a]) {
        const double v = deg_to_rad(angle_deg(*axis[3 + a]));
        end.abc[a] = (state_.absolute || g53) ? v + (g53 ? 0.0 : off.abc[a]) : pos_.abc[a] + v;
      }
    m.end = end;

    if (m.kind != MotionKind::rapid) {
      switch (state_.feed_mode) {
        case FeedMode::per_minute:
          if (state_.feed <= 0) ctx.fail(block.words.front().column, "feed move with no feed rate (F) set");
          m.feed_mm_per_min = state_.feed;
          break;
        case FeedMode::per_revolution:
          if (state_.feed <= 0) ctx.fail(block.words.front().column, "feed move with no feed per revolution (F) set");
          if (state_.spindle_rpm <= 0) ctx.fail(block.words.front().column, "G95 feed per revolution with no spindle speed (S)");
          m.feed_mm_per_min = state_.feed * state_.spindle_rpm;
          break;
        case FeedMode::inverse_time:
          if (!f || f->value <= 0)
            ctx.fail(block.words.front().column, "G93 inverse time needs a positive F on every feed move");
          m.duration_s = 60.0 / f->value;  // F is 1/min, not a length: no unit
          break;
      }
    }

    if (m.is_arc()) {
      const int n = state_.plane == 17 ? 2 : state_.plane == 18 ? 1 : 0;
      const int u = (n + 1) % 3, v = (n + 2) % 3;
      for (int a = 0; a < 3; ++a)
        if (ijk[a] && a == n) ctx.fail(ijk[a]->column, std::string("word '") + "IJK"[a] + "' is not in the arc plane");
      for (int a = 3; a < 6; ++a)
        if (axis[a]) ctx.fail(axis[a]->column, "rotary axis words in an arc move are not supported");
      if (g53) ctx.fail(g_col[kNonModal], "G53 with an arc");
      if (const gcode::Word* p = word('P')) {
        if (p->value < 1 || p->value != std::floor(p->value) || p->value > 10000)
          ctx.fail(p->column, "P (turns) must be an integer from 1 to 10000");
        m.turns = static_cast<int>(p->value);
      }
      const double su = cur[u], sv = cur[v], eu = target[u], ev = target[v];
      Vec3 centre = cur;
      if (r_word) {
        if (ijk[0] || ijk[1] || ijk[2]) ctx.fail(r_word->column, "R and I/J/K in the same arc");
        const double r = length(*r_word);
        const double du = eu - su, dv = ev - sv;
        const double chord = std::hypot(du, dv);
        if (chord < 1e-12) ctx.fail(r_word->column, "R-form arc with its end at its start");
        const double half = chord / 2;
        double h2 = r * r - half * half;
        // As LinuxCNC: a radius short of half the chord by a hair is taken as
        // exactly half the chord; more than that is an error.
        if (h2 < 0) {
          if (std::fabs(r) < half - opt_.arc_radius_tolerance_mm)
            ctx.fail(r_word->column, "arc radius " + std::to_string(std::fabs(r)) +
                                         " mm is shorter than half the chord (" + std::to_string(half) + " mm)");
          h2 = 0;
        }
        const double h = std::sqrt(h2);
        // Centre to the left of the chord for CCW small arcs, right for CW;
        // negative R picks the large arc.
        double sign = (m.kind == MotionKind::arc_ccw) ? 1.0 : -1.0;
        if (r < 0) sign = -sign;
        centre[u] = su + du / 2 - sign * h * dv / chord;
        centre[v] = sv + dv / 2 + sign * h * du / chord;
      } else {
        if (!has_arc_words) ctx.fail(block.words.front().column, "arc without I/J/K or R");
        const double ci = ijk[u] ? length(*ijk[u]) : 0.0, cj = ijk[v] ? length(*ijk[v]) : 0.0;
        centre[u] = state_.arc_absolute ? ci : su + ci;
        centre[v] = state_.arc_absolute ? cj : sv + cj;
        const double r0 = std::hypot(su - centre[u], sv - centre[v]);
        const double r1 = std::hypot(eu - centre[u], ev - centre[v]);
        if (r0 < 1e-9) ctx.fail(ijk[u] ? ijk[u]->column : ijk[v] ? ijk[v]->column : 1, "arc with zero radius");
        const double err = std::fabs(r1 - r0);
        if (err > opt_.arc_radius_tolerance_mm && err > opt_.arc_radius_tolerance_rel * r0)
          ctx.fail(block.words.front().column,
                   "arc end is not on its circle: radius to end differs from radius to start by " +
                       std::to_string(err) + " mm");
      }
      m.centre = to_machine(centre);
      if (state_.tilted) m.normal = state_.tilt.linear() * state_.plane_normal;
    } else if (has_arc_words) {
      const gcode::Word* w = r_word ? r_word : ijk[0] ? ijk[0] : ijk[1] ? ijk[1] : ijk[2];
      ctx.fail(w->column, "I/J/K or R without an arc motion (G2/G3)");
    }
    if (state_.feed_mode == FeedMode::inverse_time && m.is_cutting_feed())
      m.feed_mm_per_min = m.length() / (m.duration_s / 60.0);
    pos_ = end;
    out.push_back(std::move(m));
  } else if (state_.motion_set && has_arc_words && !dwell) {
    const gcode::Word* w = r_word ? r_word : ijk[0] ? ijk[0] : ijk[1] ? ijk[1] : ijk[2];
    ctx.fail(w->column, "arc words without an end point");
  } else if (g53) {
    ctx.fail(g_col[kNonModal], "G53 without axis words");
  }

  if (m_by_group[kStopping]) {
    const int mm = *m_by_group[kStopping];
    if (mm == 20 || mm == 300) state_.ended = true;
  }
}

}  // namespace cutsim::motion
