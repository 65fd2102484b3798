#include "cutsim/gcode/block_reader.h"

#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>

#include "cutsim/core/error.h"

namespace cutsim::gcode {

namespace {

constexpr double kDeg = 3.14159265358979323846 / 180.0;
constexpr double kToleranceEqual = 0.0001;  // LinuxCNC's TOLERANCE_EQUAL for EQ / NE
constexpr int kMaxNesting = 64;

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }
bool is_alpha(char c) { return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z'); }
bool is_digit(char c) { return c >= '0' && c <= '9'; }
char lower(char c) { return (c >= 'A' && c <= 'Z') ? static_cast<char>(c - 'A' + 'a') : c; }

struct Assignment {
  int number = 0;
  std::string name;
  double value = 0;
};

class LineParser {
public:
  LineParser(const std::string& file, int line, std::string_view text, Parameters& params, Dialect d)
      : file_(file), line_(line), t_(text), n_(text.size()), params_(params), dialect_(d) {}

  void parse(Block& b);

private:
  [[noreturn]] void fail(std::size_t at, const std::string& msg) const {
    throw ParseError(SourceLocation{file_, line_, static_cast<int>(at) + 1, std::string(t_)}, msg);
  }
  void skip_ws() {
    while (i_ < n_ && is_space(t_[i_])) ++i_;
  }
  char peek() {
    skip_ws();
    return i_ < n_ ? t_[i_] : '\0';
  }
  // Case-insensitive match of a keyword at the current position (after
  // spaces); consumes it when it matches.
  bool keyword(const char* kw) {
    skip_ws();
    std::size_t j = i_;
    for (const char* k = kw; *k; ++k) {
      while (j < n_ && is_space(t_[j])) ++j;
      if (j >= n_ || lower(t_[j]) != *k) return false;
      ++j;
    }
    i_ = j;
    return true;
  }
  double number(bool* integer_literal);
  double real_value(bool* integer_literal = nullptr);
  double expression();  // after '['
  double binary(int level);
  double unary_function(const char* name, std::size_t at);
  double parameter();  // after '#'
  int parameter_index(std::size_t at, double v);
  std::string name_in_angles();  // after '<'
  void comment(Block& b);
  void oword(Block& b, std::size_t at);
  double finite(double v, std::size_t at) {
    if (!std::isfinite(v)) fail(at, "the value is not a finite number");
    return v;
  }

  const std::string& file_;
  int line_;
  std::string_view t_;
  std::size_t n_;
  std::size_t i_ = 0;
  Parameters& params_;
  Dialect dialect_;
  int depth_ = 0;
  std::vector<Assignment> assigns_;
};

double LineParser::number(bool* integer_literal) {
  // Fast path: up to 15 significant digits, the mantissa and the power of
  // ten are exact doubles, so one division is correctly rounded: the same
  // value strtod gives. Longer numbers go through std::from_chars.
  static constexpr double kPow10[] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                                      1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};
  const std::size_t start = i_;
  bool neg = false;
  if (i_ < n_ && (t_[i_] == '+' || t_[i_] == '-')) {
    neg = t_[i_] == '-';
    ++i_;
    skip_ws();
  }
  const std::size_t digits_start = i_;
  std::uint64_t mant = 0;
  int sig = 0, frac = 0, digits = 0, points = 0;
  while (i_ < n_) {
    const char c = t_[i_];
    if (is_digit(c)) {
      ++digits;
      if (sig > 0 || c != '0') ++sig;
      if (sig <= 19) mant = mant * 10 + static_cast<std::uint64_t>(c - '0');
      if (points) ++frac;
      ++i_;
    } else if (c == '.') {
      if (++points > 1) fail(i_, "malformed number: second decimal point");
      ++i_;
    } else if (is_space(c)) {
      std::size_t j = i_;
      while (j < n_ && is_space(t_[j])) ++j;
      if (j < n_ && (is_digit(t_[j]) || (t_[j] == '.' && points == 0))) {
        i_ = j;
      } else {
        break;
      }
    } else {
      break;
    }
  }
  if (digits == 0) fail(start, "expected a number");
  if (integer_literal) *integer_literal = points == 0;
  double v;
  if (sig <= 15 && frac <= 22) {
    v = static_cast<double>(mant) / kPow10[frac];
  } else {
    // Significant text without spaces for from_chars.
    std::string buf;
    buf.reserve(i_ - digits_start);
    for (std::size_t k = digits_start; k < i_; ++k)
      if (!is_space(t_[k])) buf += t_[k];
    const auto r = std::from_chars(buf.data(), buf.data() + buf.size(), v);
    if (r.ec != std::errc() || !std::isfinite(v)) fail(start, "number out of range");
  }
  return neg ? -v : v;
}

std::string LineParser::name_in_angles() {
  const std::size_t start = i_ - 1;
  std::string name;
  while (i_ < n_ && t_[i_] != '>') {
    if (!is_space(t_[i_])) name += lower(t_[i_]);
    ++i_;
  }
  if (i_ >= n_) fail(start, "unclosed '<' in a parameter name");
  ++i_;
  if (name.empty()) fail(start, "empty parameter name");
  return name;
}

int LineParser::parameter_index(std::size_t at, double v) {
  const double r = std::round(v);
  if (std::fabs(v - r) > kToleranceEqual) fail(at, "parameter number must be an integer");
  if (r < 1 || r > Parameters::kMaxNumbered)
    fail(at, "parameter number out of range (1 to " + std::to_string(Parameters::kMaxNumbered) + ")");
  return static_cast<int>(r);
}

double LineParser::parameter() {
  const std::size_t at = i_ - 1;
  if (++depth_ > kMaxNesting) fail(at, "parameters nested too deeply");
  skip_ws();
  double v;
  if (i_ < n_ && t_[i_] == '<') {
    ++i_;
    const std::string name = name_in_angles();
    auto val = params_.named(name);
    if (!val) fail(at, "named parameter #<" + name + "> is not defined");
    v = *val;
  } else {
    bool lit = false;
    const double idx = real_value(&lit);
    v = params_.numbered(parameter_index(at, idx));
  }
  --depth_;
  return v;
}

double LineParser::unary_function(const char* name, std::size_t at) {
  skip_ws();
  if (i_ >= n_ || t_[i_] != '[') fail(at, std::string("function ") + name + " needs [ ]");
  ++i_;
  if (std::strcmp(name, "exists") == 0) {
    skip_ws();
    if (i_ >= n_ || t_[i_] != '#') fail(at, "EXISTS needs a named parameter");
    ++i_;
    skip_ws();
    if (i_ >= n_ || t_[i_] != '<') fail(at, "EXISTS needs a named parameter");
    ++i_;
    const std::string nm = name_in_angles();
    skip_ws();
    if (i_ >= n_ || t_[i_] != ']') fail(at, "expected ']'");
    ++i_;
    return params_.named(nm).has_value() ? 1.0 : 0.0;
  }
  const double a = expression();
  if (std::strcmp(name, "atan") == 0) {
    skip_ws();
    if (i_ >= n_ || t_[i_] != '/') fail(at, "ATAN needs the form ATAN[y]/[x]");
    ++i_;
    skip_ws();
    if (i_ >= n_ || t_[i_] != '[') fail(at, "ATAN needs the form ATAN[y]/[x]");
    ++i_;
    const double b = expression();
    return std::atan2(a, b) / kDeg;
  }
  if (!std::strcmp(name, "abs")) return std::fabs(a);
  if (!std::strcmp(name, "acos")) {
    if (a < -1 || a > 1) fail(at, "ACOS argument outside [-1, 1]");
    return std::acos(a) / kDeg;
  }
  if (!std::strcmp(name, "asin")) {
    if (a < -1 || a > 1) fail(at, "ASIN argument outside [-1, 1]");
    return std::asin(a) / kDeg;
  }
  if (!std::strcmp(name, "cos")) return std::cos(a * kDeg);
  if (!std::strcmp(name, "sin")) return std::sin(a * kDeg);
  if (!std::strcmp(name, "tan")) return finite(std::tan(a * kDeg), at);
  if (!std::strcmp(name, "exp")) return finite(std::exp(a), at);
  if (!std::strcmp(name, "fix")) return std::floor(a);
  if (!std::strcmp(name, "fup")) return std::ceil(a);
  if (!std::strcmp(name, "round")) return std::round(a);
  if (!std::strcmp(name, "ln")) {
    if (a <= 0) fail(at, "LN of a value not above zero");
    return std::log(a);
  }
  if (!std::strcmp(name, "sqrt")) {
    if (a < 0) fail(at, "SQRT of a negative value");
    return std::sqrt(a);
  }
  fail(at, "unknown function");
}

double LineParser::real_value(bool* integer_literal) {
  if (integer_literal) *integer_literal = false;
  skip_ws();
  if (i_ >= n_) fail(i_, "expected a value");
  const std::size_t at = i_;
  const char c = t_[i_];
  if (c == '[') {
    ++i_;
    return expression();
  }
  if (c == '#') {
    ++i_;
    return parameter();
  }
  if (c == '-' || c == '+') {
    // A sign before a number is part of it; before anything else it is unary.
    std::size_t j = i_ + 1;
    while (j < n_ && is_space(t_[j])) ++j;
    if (j < n_ && (is_digit(t_[j]) || t_[j] == '.')) return number(integer_literal);
    ++i_;
    if (++depth_ > kMaxNesting) fail(at, "expression nested too deeply");
    const double v = real_value();
    --depth_;
    return c == '-' ? -v : v;
  }
  if (is_digit(c) || c == '.') return number(integer_literal);
  if (is_alpha(c)) {
    static const char* kFunctions[] = {"abs", "acos", "asin", "atan", "cos", "exists", "exp", "fix", "fup",
                                       "round", "ln", "sin", "sqrt", "tan"};
    for (const char* f : kFunctions)
      if (keyword(f)) {
        if (peek() == '[') {
          if (++depth_ > kMaxNesting) fail(at, "expression nested too deeply");
          const double v = unary_function(f, at);
          --depth_;
          return finite(v, at);
        }
        i_ = at;
      }
  }
  if (c == '#' || c == '[') fail(at, "expected a value");
  fail(at, "expected a number, a parameter or an expression");
}

// Binary operator precedence as LinuxCNC: ** > * / MOD > + - >
// EQ NE GT GE LT LE > AND OR XOR; left associative.
double LineParser::binary(int level) {
  if (level > 4) return real_value();
  double a = binary(level + 1);
  for (;;) {
    skip_ws();
    const std::size_t at = i_;
    if (i_ >= n_) return a;
    if (level == 4) {
      if (i_ + 1 < n_ && t_[i_] == '*' && t_[i_ + 1] == '*') {
        i_ += 2;
        const double b = binary(level + 1);
        if (a < 0 && b != std::floor(b)) fail(at, "negative base to a non-integer power");
        if (a == 0 && b < 0) fail(at, "zero to a negative power");
        a = finite(std::pow(a, b), at);
        continue;
      }
      return a;
    }
    if (level == 3) {
      if (t_[i_] == '*' && !(i_ + 1 < n_ && t_[i_ + 1] == '*')) {
        ++i_;
        a = finite(a * binary(level + 1), at);
        continue;
      }
      if (t_[i_] == '/') {
        ++i_;
        const double b = binary(level + 1);
        if (b == 0) fail(at, "division by zero");
        a = finite(a / b, at);
        continue;
      }
      if (keyword("mod")) {
        const double b = binary(level + 1);
        if (b == 0) fail(at, "MOD by zero");
        a = std::fmod(a, b);
        if (a < 0) a += std::fabs(b);
        continue;
      }
      return a;
    }
    if (level == 2) {
      if (t_[i_] == '+') { ++i_; a = finite(a + binary(level + 1), at); continue; }
      if (t_[i_] == '-') { ++i_; a = finite(a - binary(level + 1), at); continue; }
      return a;
    }
    if (level == 1) {
      if (keyword("eq")) { a = std::fabs(a - binary(level + 1)) < kToleranceEqual; continue; }
      if (keyword("ne")) { a = std::fabs(a - binary(level + 1)) >= kToleranceEqual; continue; }
      if (keyword("gt")) { a = a > binary(level + 1); continue; }
      if (keyword("ge")) { a = a >= binary(level + 1); continue; }
      if (keyword("lt")) { a = a < binary(level + 1); continue; }
      if (keyword("le")) { a = a <= binary(level + 1); continue; }
      return a;
    }
    // level 0
    if (keyword("and")) { const double b = binary(level + 1); a = (a != 0) && (b != 0); continue; }
    if (keyword("or")) { const double b = binary(level + 1); a = (a != 0) || (b != 0); continue; }
    if (keyword("xor")) { const double b = binary(level + 1); a = (a != 0) != (b != 0); continue; }
    return a;
  }
}

double LineParser::expression() {
  const std::size_t at = i_ - 1;
  if (++depth_ > kMaxNesting) fail(at, "expression nested too deeply");
  const double v = binary(0);
  skip_ws();
  if (i_ >= n_) fail(at, "unclosed '['");
  if (t_[i_] != ']') fail(i_, "expected ']' or an operator");
  ++i_;
  --depth_;
  return v;
}

void LineParser::comment(Block& b) {
  const std::size_t open = i_;
  std::size_t j = open + 1;
  while (j < n_ && t_[j] != ')') {
    if (t_[j] == '(') fail(j, "nested '(' in a comment");
    ++j;
  }
  if (j >= n_) fail(open, "unclosed comment '('");
  const std::string_view body = t_.substr(open + 1, j - open - 1);
  if (body.size() >= 4 && lower(body[0]) == 'm' && lower(body[1]) == 's' && lower(body[2]) == 'g' && body[3] == ',')
    b.message = std::string(body.substr(4));
  i_ = j + 1;
}

void LineParser::oword(Block& b, std::size_t at) {
  OWord& o = b.o;
  o.column = static_cast<int>(at) + 1;
  skip_ws();
  if (i_ < n_ && t_[i_] == '<') {
    ++i_;
    o.name = name_in_angles();
  } else {
    bool lit = false;
    const double v = real_value(&lit);
    if (v < 0 || v != std::floor(v) || v > 1e15) fail(at, "O-word number must be a non-negative integer");
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.0f", v);
    o.name = buf;
  }
  if (dialect_ == Dialect::fanuc) {
    o.kind = OKind::program_number;
    return;
  }
  struct K { const char* kw; OKind k; };
  static const K kKinds[] = {{"endsub", OKind::endsub}, {"sub", OKind::sub}, {"call", OKind::call},
                             {"return", OKind::ret}, {"do", OKind::do_}, {"endwhile", OKind::endwhile},
                             {"while", OKind::while_}, {"elseif", OKind::elseif}, {"else", OKind::else_},
                             {"endif", OKind::endif}, {"if", OKind::if_}, {"endrepeat", OKind::endrepeat},
                             {"repeat", OKind::repeat}, {"break", OKind::break_}, {"continue", OKind::continue_}};
  for (const K& k : kKinds)
    if (keyword(k.kw)) { o.kind = k.k; break; }
  if (o.kind == OKind::none) fail(i_ < n_ ? i_ : at, "expected an O-word keyword (sub, call, while, if, ...)");
  switch (o.kind) {
    case OKind::call:
      while (peek() == '[') {
        ++i_;
        o.args.push_back(expression());
        if (o.args.size() > 30) fail(at, "more than 30 call arguments");
      }
      break;
    case OKind::while_: case OKind::if_: case OKind::elseif: case OKind::repeat:
      if (peek() != '[') fail(i_ < n_ ? i_ : at, "expected '[' with the condition or count");
      ++i_;
      o.value = expression();
      o.has_value = true;
      break;
    case OKind::ret: case OKind::endsub:
      if (peek() == '[') {
        ++i_;
        o.value = expression();
        o.has_value = true;
      }
      break;
    default:
      break;
  }
}

void LineParser::parse(Block& b) {
  bool first = true;
  while (i_ < n_) {
    const char c = t_[i_];
    if (is_space(c)) { ++i_; continue; }
    if (c == ';') break;
    if (c == '%') {
      for (std::size_t k = i_ + 1; k < n_; ++k)
        if (!is_space(t_[k])) fail(k, "text after '%'");
      break;
    }
    if (c == '(') { comment(b); continue; }
    if (c == ')') fail(i_, "')' without '('");
    if (c == '#') {
      const std::size_t at = i_;
      ++i_;
      skip_ws();
      Assignment a;
      if (i_ < n_ && t_[i_] == '<') {
        ++i_;
        a.name = name_in_angles();
      } else {
        a.number = parameter_index(at, real_value());
      }
      skip_ws();
      if (i_ >= n_ || t_[i_] != '=') fail(i_ < n_ ? i_ : at, "expected '=' after a parameter at the start of a segment");
      ++i_;
      a.value = real_value();
      assigns_.push_back(std::move(a));
      first = false;
      continue;
    }
    if (is_alpha(c)) {
      const char L = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
      const std::size_t at = i_;
      ++i_;
      if (L == 'O') {
        if (!b.words.empty() && !(b.words.size() == 1 && b.words[0].letter == 'N'))
          fail(at, "an O-word must start the block");
        if (b.o.kind != OKind::none) fail(at, "two O-words in one block");
        oword(b, at);
        first = false;
        continue;
      }
      if (b.o.kind != OKind::none && b.o.kind != OKind::program_number)
        fail(at, "words after an O-word control statement");
      Word w;
      w.letter = L;
      w.column = static_cast<int>(at) + 1;
      skip_ws();
      w.value_column = static_cast<int>(i_) + 1;
      if (i_ >= n_) fail(at, std::string("word '") + L + "' has no value");
      const char v0 = t_[i_];
      if (!(is_digit(v0) || v0 == '.' || v0 == '-' || v0 == '+' || v0 == '[' || v0 == '#' || is_alpha(v0)))
        fail(at, std::string("word '") + L + "' has no value");
      if (is_alpha(v0) && peek() != '[') {
        // A letter directly after a letter: the first word has no value,
        // unless what follows is a function name with '['.
        std::size_t j = i_;
        while (j < n_ && is_alpha(t_[j])) ++j;
        while (j < n_ && is_space(t_[j])) ++j;
        if (j >= n_ || t_[j] != '[') fail(at, std::string("word '") + L + "' has no value");
      }
      w.value = real_value(&w.integer_literal);
      b.words.push_back(w);
      first = false;
      continue;
    }
    if (c == '/' && first) {  // block delete marker; the caller decides whether to run the line
      ++i_;
      first = false;
      continue;
    }
    if (is_digit(c) || c == '.' || c == '-' || c == '+') fail(i_, "number without a letter");
    if (static_cast<unsigned char>(c) < 32 || static_cast<unsigned char>(c) >= 127)
      fail(i_, "unexpected control or non-ASCII character");
    fail(i_, std::string("unexpected character '") + c + "'");
  }
  for (const Assignment& a : assigns_) {
    if (a.name.empty()) params_.set_numbered(a.number, a.value);
    else params_.set_named(a.name, a.value);
  }
  b.has_assignments = !assigns_.empty();
}

}  // namespace

void parse_line(const std::string& file, int line_no, std::string_view text, Parameters& params, Dialect dialect,
                Block& block) {
  block.line = line_no;
  block.text.assign(text.data(), text.size());
  block.words.clear();
  block.message.clear();
  block.o = OWord{};
  block.has_assignments = false;
  LineParser p(file, line_no, text, params, dialect);
  p.parse(block);
}

BlockReader::BlockReader(std::istream& in, std::string file_name, Dialect dialect)
    : src_(in, std::move(file_name)), dialect_(dialect) {}

bool BlockReader::next(Block& block) {
  std::string_view line;
  while (src_.next(line)) {
    gcode::parse_line(src_.file(), src_.line_number(), line, params_, dialect_, block);
    if (!block.words.empty() || block.o.kind != OKind::none) return true;
  }
  return false;
}

void BlockReader::parse_line(const std::string& file, int line_no, const std::string& text, Block& block) {
  Parameters p;
  gcode::parse_line(file, line_no, text, p, Dialect::rs274ngc, block);
}

}  // namespace cutsim::gcode
