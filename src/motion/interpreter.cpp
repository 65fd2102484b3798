#include "cutsim/motion/interpreter.h"

#include <cmath>
#include <optional>

#include "cutsim/core/error.h"

namespace cutsim::motion {

namespace {

constexpr double kMmPerInch = 25.4;

struct Ctx {
  const std::string& file;
  const gcode::Block& block;
  [[noreturn]] void fail(int column, const std::string& msg) const {
    throw ParseError(SourceLocation{file, block.line, column, block.text}, msg);
  }
};

// Modal groups of the G codes cutsim knows (codes in tenths).
enum Group { kNone = -1, kMotion = 1, kPlane = 2, kDistance = 3, kFeedMode = 5, kUnits = 6,
             kCutterComp = 7, kToolLength = 8, kCannedReturn = 10, kCoordSys = 12,
             kPathMode = 13, kNonModal = 0 };

Group g_group(int t) {
  switch (t) {
    case 0: case 10: case 20: case 30: case 800: return kMotion;
    case 170: case 180: case 190: return kPlane;
    case 900: case 910: return kDistance;
    case 940: return kFeedMode;
    case 200: case 210: return kUnits;
    case 400: return kCutterComp;
    case 490: return kToolLength;
    case 540: return kCoordSys;
    case 610: case 640: return kPathMode;
    case 40: return kNonModal;
    default: return kNone;
  }
}

enum MGroup { kMNone = -1, kStopping = 4, kToolChange = 6, kSpindle = 7, kCoolant = 8 };

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

}  // namespace

Interpreter::Interpreter(std::string file_name, InterpreterOptions options)
    : file_(std::move(file_name)), opt_(options), pos_(options.initial) {}

void Interpreter::execute(const gcode::Block& block, std::vector<Move>& out) {
  const Ctx ctx{file_, block};
  if (state_.ended) {
    warnings_.push_back({block.line, 1, "block after M2/M30 is ignored"});
    return;
  }

  // Collect the words, checking letters, modal groups and repeats.
  std::optional<int> g_by_group[16];
  int g_col_by_group[16] = {};
  std::optional<int> m_by_group[10];
  std::optional<double> axis[6];  // X Y Z A B C
  int axis_col[6] = {};
  std::optional<double> ijk[3];
  int ijk_col[3] = {};
  std::optional<double> r_word, f_word, s_word, p_word;
  int r_col = 0, p_col = 0;
  std::optional<int> t_word;
  bool seen[26] = {};

  for (const gcode::Word& w : block.words) {
    const char L = w.letter;
    if (L == 'G') {
      const int t = gcode::code_tenths(w.value);
      const Group g = g_group(t);
      if (g == kNone) {
        if (t == 410 || t == 420 || t == 411 || t == 421)
          ctx.fail(w.column, code_text('G', w.value) + ": cutter radius compensation is not supported");
        if (t >= 730 && t <= 890)
          ctx.fail(w.column, code_text('G', w.value) + ": canned cycles are not supported");
        ctx.fail(w.column, "unknown G code " + code_text('G', w.value));
      }
      if (g_by_group[g])
        ctx.fail(w.column, code_text('G', w.value) + " conflicts with G" +
                               std::to_string(*g_by_group[g] / 10) + " in the same modal group");
      g_by_group[g] = t;
      g_col_by_group[g] = w.column;
      continue;
    }
    if (L == 'M') {
      const int t = gcode::code_tenths(w.value);
      const MGroup g = m_group(t);
      if (g == kMNone) ctx.fail(w.column, "unknown M code " + code_text('M', w.value));
      if (m_by_group[g])
        ctx.fail(w.column, code_text('M', w.value) + " conflicts with M" +
                               std::to_string(*m_by_group[g] / 10) + " in the same modal group");
      m_by_group[g] = t;
      continue;
    }
    if (L == 'N') {
      if (&w != &block.words.front()) ctx.fail(w.column, "N word must come first in the block");
      continue;
    }
    const int li = L - 'A';
    if (seen[li]) ctx.fail(w.column, std::string("word '") + L + "' appears twice in the block");
    seen[li] = true;
    switch (L) {
      case 'X': axis[0] = w.value; axis_col[0] = w.column; break;
      case 'Y': axis[1] = w.value; axis_col[1] = w.column; break;
      case 'Z': axis[2] = w.value; axis_col[2] = w.column; break;
      case 'A': axis[3] = w.value; axis_col[3] = w.column; break;
      case 'B': axis[4] = w.value; axis_col[4] = w.column; break;
      case 'C': axis[5] = w.value; axis_col[5] = w.column; break;
      case 'I': ijk[0] = w.value; ijk_col[0] = w.column; break;
      case 'J': ijk[1] = w.value; ijk_col[1] = w.column; break;
      case 'K': ijk[2] = w.value; ijk_col[2] = w.column; break;
      case 'R': r_word = w.value; r_col = w.column; break;
      case 'F':
        if (w.value < 0) ctx.fail(w.value_column, "negative feed rate");
        f_word = w.value; break;
      case 'S':
        if (w.value < 0) ctx.fail(w.value_column, "negative spindle speed");
        s_word = w.value; break;
      case 'P': p_word = w.value; p_col = w.column; break;
      case 'T':
        if (w.value < 0 || w.value != std::floor(w.value))
          ctx.fail(w.value_column, "tool number must be a non-negative integer");
        t_word = static_cast<int>(w.value); break;
      case 'H': case 'D': break;  // tool length/diameter register: no offsets yet
      default:
        ctx.fail(w.column, std::string("unknown word '") + L + "'");
    }
  }

  // Order of execution follows RS274NGC: feed, spindle, tool select, tool
  // change, plane, units, distance mode, dwell, motion, stop.
  if (g_by_group[kUnits]) state_.inches = (*g_by_group[kUnits] == 200);
  const double unit = state_.inches ? kMmPerInch : 1.0;
  if (f_word) state_.feed_mm_per_min = *f_word * unit;
  if (s_word) state_.spindle_rpm = *s_word;
  if (t_word) state_.tool_selected = *t_word;
  if (m_by_group[kSpindle]) {
    const int m = *m_by_group[kSpindle];
    state_.spindle_dir = m == 30 ? 1 : m == 40 ? -1 : 0;
  }
  if (m_by_group[kToolChange]) state_.tool_in_spindle = state_.tool_selected;
  if (g_by_group[kPlane]) {
    const int t = *g_by_group[kPlane];
    state_.plane_axis = t == 170 ? 2 : t == 180 ? 1 : 0;
  }
  if (g_by_group[kDistance]) state_.absolute = (*g_by_group[kDistance] == 900);

  const bool dwell = g_by_group[kNonModal] && *g_by_group[kNonModal] == 40;
  if (dwell && !p_word) ctx.fail(g_col_by_group[kNonModal], "G4 needs a P word (seconds)");

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

  const bool has_axis = axis[0] || axis[1] || axis[2] || axis[3] || axis[4] || axis[5];
  const bool has_arc_words = ijk[0] || ijk[1] || ijk[2] || r_word;
  if (has_axis && !dwell) {
    if (!state_.motion_set) {
      int col = axis_col[0] ? axis_col[0] : axis_col[1] ? axis_col[1] : axis_col[2] ? axis_col[2]
              : axis_col[3] ? axis_col[3] : axis_col[4] ? axis_col[4] : axis_col[5];
      ctx.fail(col, "axis words without an active motion mode (G0, G1, G2 or G3)");
    }
    Move m;
    m.line = block.line;
    m.text = std::make_shared<const std::string>(block.text);
    m.kind = state_.motion;
    m.start = pos_;
    m.tool = state_.tool_in_spindle;
    m.plane_axis = state_.plane_axis;
    AxisValues end = pos_;
    for (int a = 0; a < 3; ++a)
      if (axis[a]) end.xyz[a] = (state_.absolute ? 0.0 : pos_.xyz[a]) + *axis[a] * unit;
    for (int a = 0; a < 3; ++a)
      if (axis[3 + a])
        end.abc[a] = (state_.absolute ? 0.0 : pos_.abc[a]) + deg_to_rad(*axis[3 + a]);
    m.end = end;
    if (m.kind != MotionKind::rapid) {
      if (state_.feed_mm_per_min <= 0)
        ctx.fail(block.words.front().column, "feed move with no feed rate (F) set");
      m.feed_mm_per_min = state_.feed_mm_per_min;
    }
    if (m.is_arc()) {
      const int n = state_.plane_axis;
      const int u = (n + 1) % 3, v = (n + 2) % 3;
      static const char kIjk[] = {'I', 'J', 'K'};
      for (int a = 0; a < 3; ++a)
        if (ijk[a] && a == n) ctx.fail(ijk_col[a], std::string("word '") + kIjk[a] + "' is not in the arc plane");
      if (axis[3] || axis[4] || axis[5])
        ctx.fail(axis_col[3] ? axis_col[3] : axis_col[4] ? axis_col[4] : axis_col[5],
                 "rotary axis words in an arc move are not supported");
      if (p_word) {
        if (*p_word < 1 || *p_word != std::floor(*p_word))
          ctx.fail(p_col, "P (turns) must be a positive integer");
        m.turns = static_cast<int>(*p_word);
      }
      const double su = pos_.xyz[u], sv = pos_.xyz[v];
      const double eu = end.xyz[u], ev = end.xyz[v];
      if (r_word) {
        if (ijk[0] || ijk[1] || ijk[2]) ctx.fail(r_col, "R and I/J/K in the same arc");
        const double r = *r_word * unit;
        const double du = eu - su, dv = ev - sv;
        const double chord = std::hypot(du, dv);
        if (chord < 1e-12) ctx.fail(r_col, "R-form arc with its end at its start");
        const double half = chord / 2;
        double h2 = r * r - half * half;
        // As LinuxCNC: a radius short of half the chord by a hair is taken as
        // exactly half the chord; more than that is an error.
        if (h2 < 0) {
          if (std::fabs(r) < half - opt_.arc_radius_tolerance_mm)
            ctx.fail(r_col, "arc radius " + std::to_string(std::fabs(r)) +
                                " mm is shorter than half the chord (" + std::to_string(half) + " mm)");
          h2 = 0;
        }
        const double h = std::sqrt(h2);
        // Centre to the left of the chord for CCW small arcs, right for CW;
        // negative R picks the large arc.
        double sign = (m.kind == MotionKind::arc_ccw) ? 1.0 : -1.0;
        if (r < 0) sign = -sign;
        const double mu = su + du / 2, mv = sv + dv / 2;
        m.centre = pos_.xyz;
        m.centre[u] = mu - sign * h * dv / chord;
        m.centre[v] = mv + sign * h * du / chord;
      } else {
        if (!has_arc_words) ctx.fail(block.words.front().column, "arc without I/J/K or R");
        m.centre = pos_.xyz;
        m.centre[u] = su + (ijk[u] ? *ijk[u] * unit : 0.0);
        m.centre[v] = sv + (ijk[v] ? *ijk[v] * unit : 0.0);
        const double r0 = m.arc_start_radius();
        const double r1 = m.arc_end_radius();
        if (r0 < 1e-9) ctx.fail(ijk_col[u] ? ijk_col[u] : ijk_col[v], "arc with zero radius");
        const double err = std::fabs(r1 - r0);
        if (err > opt_.arc_radius_tolerance_mm && err > opt_.arc_radius_tolerance_rel * r0)
          ctx.fail(block.words.front().column,
                   "arc end is not on its circle: radius to end differs from radius to start by " +
                       std::to_string(err) + " mm");
      }
    } else if (has_arc_words) {
      ctx.fail(r_word ? r_col : ijk_col[0] ? ijk_col[0] : ijk_col[1] ? ijk_col[1] : ijk_col[2],
               "I/J/K or R without an arc motion (G2/G3)");
    }
    pos_ = end;
    out.push_back(std::move(m));
  } else if (state_.motion_set && has_arc_words && !dwell) {
    ctx.fail(r_word ? r_col : ijk_col[0] ? ijk_col[0] : ijk_col[1] ? ijk_col[1] : ijk_col[2],
             "arc words without an end point");
  }

  if (m_by_group[kStopping]) {
    const int m = *m_by_group[kStopping];
    if (m == 20 || m == 300) state_.ended = true;
  }
}

}  // namespace cutsim::motion
