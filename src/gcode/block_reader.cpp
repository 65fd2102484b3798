#include "cutsim/gcode/block_reader.h"

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>

#include "cutsim/core/error.h"

namespace cutsim::gcode {

namespace {

[[noreturn]] void fail(const std::string& file, int line, std::size_t index,
                       const std::string& text, const std::string& msg) {
  throw ParseError(SourceLocation{file, line, static_cast<int>(index) + 1, text}, msg);
}

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

}  // namespace

BlockReader::BlockReader(std::istream& in, std::string file_name)
    : in_(in), file_(std::move(file_name)) {}

bool BlockReader::next(Block& block) {
  while (std::getline(in_, line_)) {
    ++line_no_;
    if (!line_.empty() && line_.back() == '\r') line_.pop_back();
    parse_line(file_, line_no_, line_, block);
    if (!block.words.empty()) return true;
  }
  if (in_.bad()) throw InputError(file_, "read error");
  return false;
}

void BlockReader::parse_line(const std::string& file, int line_no, const std::string& text,
                             Block& block) {
  block.line = line_no;
  block.text = text;
  block.words.clear();
  block.message.clear();
  const std::size_t n = text.size();
  std::size_t i = 0;
  while (i < n) {
    const char c = text[i];
    if (is_space(c)) { ++i; continue; }
    if (c == ';') break;
    if (c == '%') {
      // A '%' line marks the start or end of a program tape.
      for (std::size_t k = i + 1; k < n; ++k)
        if (!is_space(text[k])) fail(file, line_no, k, text, "text after '%'");
      break;
    }
    if (c == '(') {
      const std::size_t close = text.find(')', i + 1);
      if (close == std::string::npos) fail(file, line_no, i, text, "unclosed comment '('");
      const std::string body = text.substr(i + 1, close - i - 1);
      if (body.find('(') != std::string::npos)
        fail(file, line_no, i + 1 + body.find('('), text, "nested '(' in a comment");
      std::string head;
      for (char ch : body.substr(0, 4)) head += static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
      if (head == "MSG,") block.message = body.substr(4);
      i = close + 1;
      continue;
    }
    if (c == ')') fail(file, line_no, i, text, "')' without '('");
    if (std::isalpha(static_cast<unsigned char>(c))) {
      Word w;
      w.letter = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
      w.column = static_cast<int>(i) + 1;
      std::size_t j = i + 1;
      while (j < n && is_space(text[j])) ++j;
      w.value_column = static_cast<int>(j) + 1;
      // A number: optional sign, digits with at most one decimal point.
      std::string num;
      std::size_t k = j;
      if (k < n && (text[k] == '+' || text[k] == '-')) num += text[k++];
      int digits = 0, points = 0;
      while (k < n) {
        const char d = text[k];
        if (std::isdigit(static_cast<unsigned char>(d))) { ++digits; num += d; ++k; }
        else if (d == '.') {
          if (++points > 1) fail(file, line_no, k, text, std::string("malformed number in word '") + w.letter + "': second decimal point");
          num += d; ++k;
        } else if (is_space(d) && digits > 0) {
          // RS274NGC allows spaces inside numbers; keep reading if a digit follows.
          std::size_t m = k;
          while (m < n && is_space(text[m])) ++m;
          if (m < n && (std::isdigit(static_cast<unsigned char>(text[m])) || text[m] == '.')) k = m;
          else break;
        } else break;
      }
      if (digits == 0) {
        if (k < n && (text[k] == '#' || text[k] == '['))
          fail(file, line_no, k, text, "parameters and expressions ('#', '[') are not supported");
        fail(file, line_no, i, text, std::string("word '") + w.letter + "' has no number");
      }
      errno = 0;
      w.value = std::strtod(num.c_str(), nullptr);
      if (!std::isfinite(w.value) || errno == ERANGE)
        fail(file, line_no, j, text, std::string("number out of range in word '") + w.letter + "'");
      block.words.push_back(w);
      i = k;
      continue;
    }
    if (c == '/' && block.words.empty())
      fail(file, line_no, i, text, "block delete '/' is not supported");
    if (c == '#' || c == '[')
      fail(file, line_no, i, text, "parameters and expressions ('#', '[') are not supported");
    if (std::isdigit(static_cast<unsigned char>(c)) || c == '.' || c == '-' || c == '+')
      fail(file, line_no, i, text, "number without a letter");
    if (static_cast<unsigned char>(c) < 32 || static_cast<unsigned char>(c) >= 127)
      fail(file, line_no, i, text, "unexpected control or non-ASCII character");
    fail(file, line_no, i, text, std::string("unexpected character '") + c + "'");
  }
}

}  // namespace cutsim::gcode
