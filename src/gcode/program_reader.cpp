#include "cutsim/gcode/program_reader.h"

#include <cctype>
#include <cmath>

#include "cutsim/core/error.h"
#include "cutsim/gcode/block_reader.h"

namespace cutsim::gcode {

namespace {

char lower(char c) { return static_cast<char>(std::tolower(static_cast<unsigned char>(c))); }

// Recognises an O-word line without evaluating anything: its name and kind.
bool scan_oword(std::string_view s, Dialect d, std::string& name, OKind& kind) {
  std::size_t i = 0;
  const std::size_t n = s.size();
  auto ws = [&] { while (i < n && (s[i] == ' ' || s[i] == '\t' || s[i] == '\r')) ++i; };
  ws();
  if (i < n && s[i] == '/') { ++i; ws(); }
  if (i < n && lower(s[i]) == 'n') {
    ++i;
    while (i < n && (std::isdigit(static_cast<unsigned char>(s[i])) || s[i] == ' ' || s[i] == '.')) ++i;
  }
  ws();
  if (i >= n || lower(s[i]) != 'o') return false;
  ++i;
  ws();
  name.clear();
  if (i < n && s[i] == '<') {
    ++i;
    while (i < n && s[i] != '>') {
      if (s[i] != ' ' && s[i] != '\t') name += lower(s[i]);
      ++i;
    }
    if (i >= n) return false;
    ++i;
  } else {
    while (i < n && (std::isdigit(static_cast<unsigned char>(s[i])) || s[i] == ' ')) {
      if (s[i] != ' ') name += s[i];
      ++i;
    }
    // Canonical form of a number: no leading zeros.
    std::size_t z = 0;
    while (z + 1 < name.size() && name[z] == '0') ++z;
    name.erase(0, z);
    if (name.empty()) return false;
  }
  if (d == Dialect::fanuc) {
    kind = OKind::program_number;
    return true;
  }
  std::string kw;
  ws();
  while (i < n && std::isalpha(static_cast<unsigned char>(s[i]))) kw += lower(s[i++]);
  static const std::pair<const char*, OKind> kKinds[] = {
      {"sub", OKind::sub}, {"endsub", OKind::endsub}, {"call", OKind::call}, {"return", OKind::ret},
      {"do", OKind::do_}, {"while", OKind::while_}, {"endwhile", OKind::endwhile}, {"if", OKind::if_},
      {"elseif", OKind::elseif}, {"else", OKind::else_}, {"endif", OKind::endif}, {"repeat", OKind::repeat},
      {"endrepeat", OKind::endrepeat}, {"break", OKind::break_}, {"continue", OKind::continue_}};
  for (const auto& [k, v] : kKinds)
    if (kw == k) {
      kind = v;
      return true;
    }
  return false;
}

const char* kind_name(OKind k) {
  switch (k) {
    case OKind::sub: return "sub"; case OKind::endsub: return "endsub"; case OKind::call: return "call";
    case OKind::ret: return "return"; case OKind::do_: return "do"; case OKind::while_: return "while";
    case OKind::endwhile: return "endwhile"; case OKind::if_: return "if"; case OKind::elseif: return "elseif";
    case OKind::else_: return "else"; case OKind::endif: return "endif"; case OKind::repeat: return "repeat";
    case OKind::endrepeat: return "endrepeat"; case OKind::break_: return "break";
    case OKind::continue_: return "continue"; default: return "?";
  }
}

}  // namespace

ProgramReader::ProgramReader(std::istream& in, std::string file, ReaderOptions opt)
    : src_(in, file, opt.max_line_bytes), file_(std::move(file)), opt_(opt) {}

void ProgramReader::fail(const Block& b, int column, const std::string& msg) const {
  throw ParseError(SourceLocation{file_, b.line, column, b.text}, msg);
}

bool ProgramReader::read_line(std::string_view& line) {
  if (!src_.next(line)) return false;
  max_line_ = std::max(max_line_, src_.line_number());
  if (++executed_ > opt_.max_lines_executed && opt_.max_lines_executed > 0)
    throw ParseError(SourceLocation{file_, src_.line_number(), 0, {}},
                     "more than " + std::to_string(opt_.max_lines_executed) + " lines executed (a runaway loop?)");
  return true;
}

void ProgramReader::parse(std::string_view line, Block& b) {
  parse_line(file_, src_.line_number(), line, params_, opt_.dialect, b);
}

OKind ProgramReader::skip_to(const std::string& name, std::initializer_list<OKind> kinds, const Block& from, Block& b) {
  std::string_view line;
  std::string nm;
  OKind k = OKind::none;
  while (read_line(line)) {
    if (!scan_oword(line, opt_.dialect, nm, k) || nm != name) continue;
    for (OKind want : kinds)
      if (k == want) {
        parse(line, b);
        return k;
      }
  }
  std::string list;
  for (OKind want : kinds) list += std::string(list.empty() ? "" : " or ") + "o" + name + " " + kind_name(want);
  fail(from, from.o.column, "no " + list + " after this line");
}

LinePosition ProgramReader::find_sub(const std::string& name, const Block& call) {
  auto it = subs_.find(name);
  if (it != subs_.end()) return it->second;
  // Not seen yet: look ahead, remembering every sub on the way.
  const LinePosition back = src_.tell();
  std::string_view line;
  std::string nm;
  OKind k;
  while (src_.next(line)) {
    max_line_ = std::max(max_line_, src_.line_number());
    if (scan_oword(line, opt_.dialect, nm, k) && k == OKind::sub && !subs_.count(nm)) subs_[nm] = src_.tell();
  }
  src_.seek(back);
  it = subs_.find(name);
  if (it == subs_.end()) fail(call, call.o.column, "subroutine o" + name + " is not defined in this file");
  return it->second;
}

LinePosition ProgramReader::find_program(const std::string& number, const Block& call) {
  auto it = programs_.find(number);
  if (it != programs_.end()) return it->second;
  const LinePosition back = src_.tell();
  src_.seek(LinePosition{0, 1});
  std::string_view line;
  std::string nm;
  OKind k;
  while (src_.next(line))
    if (scan_oword(line, opt_.dialect, nm, k) && k == OKind::program_number && !programs_.count(nm))
      programs_[nm] = src_.tell();
  src_.seek(back);
  it = programs_.find(number);
  if (it == programs_.end()) fail(call, 1, "subprogram O" + number + " is not in this file");
  return it->second;
}

void ProgramReader::handle_oword(Block& b) {
  const OWord o = b.o;
  auto top_is = [&](FrameKind k) { return !stack_.empty() && stack_.back().kind == k && stack_.back().name == o.name; };
  switch (o.kind) {
    case OKind::sub: {
      subs_[o.name] = src_.tell();
      skip_to(o.name, {OKind::endsub}, b, scratch_);
      return;
    }
    case OKind::call: {
      const LinePosition body = find_sub(o.name, b);
      if (static_cast<int>(stack_.size()) >= opt_.max_call_depth)
        fail(b, o.column, "subroutine calls nested deeper than " + std::to_string(opt_.max_call_depth));
      stack_.push_back(Frame{FrameKind::call, o.name, src_.tell(), 0, b.line});
      params_.push_call(o.args);
      src_.seek(body);
      return;
    }
    case OKind::ret: case OKind::endsub: {
      // Unwind loops and conditionals inside the subroutine.
      while (!stack_.empty() && stack_.back().kind != FrameKind::call) stack_.pop_back();
      if (stack_.empty()) {
        if (o.kind == OKind::endsub) fail(b, o.column, "o" + o.name + " endsub without a call");
        fail(b, o.column, "o" + o.name + " return outside a subroutine");
      }
      if (stack_.back().name != o.name)
        fail(b, o.column, "o" + o.name + " " + kind_name(o.kind) + " inside subroutine o" + stack_.back().name);
      if (o.has_value) params_.set_named("_value", o.value);
      const LinePosition back = stack_.back().pos;
      stack_.pop_back();
      params_.pop_call();
      src_.seek(back);
      return;
    }
    case OKind::do_:
      stack_.push_back(Frame{FrameKind::do_, o.name, src_.tell(), 0, b.line});
      return;
    case OKind::while_: {
      if (top_is(FrameKind::do_)) {  // end of a do-while
        if (o.value != 0) src_.seek(stack_.back().pos);
        else stack_.pop_back();
        return;
      }
      if (o.value != 0) {
        // next() records where this while line starts, to test it again.
        if (!top_is(FrameKind::while_)) stack_.push_back(Frame{FrameKind::while_, o.name, {}, 0, b.line});
        return;
      }
      if (top_is(FrameKind::while_)) stack_.pop_back();
      skip_to(o.name, {OKind::endwhile}, b, scratch_);
      return;
    }
    case OKind::endwhile: {
      if (!top_is(FrameKind::while_)) fail(b, o.column, "o" + o.name + " endwhile without its while");
      src_.seek(stack_.back().pos);
      return;
    }
    case OKind::repeat: {
      if (!(o.value < 1e12)) fail(b, o.column, "repeat count too large");
      const long long count = o.value > 0 ? std::llround(o.value) : 0;
      if (count <= 0) {
        skip_to(o.name, {OKind::endrepeat}, b, scratch_);
        return;
      }
      stack_.push_back(Frame{FrameKind::repeat, o.name, src_.tell(), count, b.line});
      return;
    }
    case OKind::endrepeat: {
      if (!top_is(FrameKind::repeat)) fail(b, o.column, "o" + o.name + " endrepeat without its repeat");
      if (--stack_.back().remaining > 0) src_.seek(stack_.back().pos);
      else stack_.pop_back();
      return;
    }
    case OKind::if_: {
      Block& s = scratch_;
      if (o.value != 0) {
        stack_.push_back(Frame{FrameKind::if_, o.name, {}, 0, b.line});
        return;
      }
      for (;;) {
        const OKind k = skip_to(o.name, {OKind::elseif, OKind::else_, OKind::endif}, b, s);
        if (k == OKind::endif) return;
        if (k == OKind::else_ || s.o.value != 0) {
          stack_.push_back(Frame{FrameKind::if_, o.name, {}, 0, b.line});
          return;
        }
      }
    }
    case OKind::elseif: case OKind::else_: {
      // Reached at the end of a taken branch: skip to endif.
      if (!top_is(FrameKind::if_)) fail(b, o.column, "o" + o.name + " " + kind_name(o.kind) + " without its if");
      stack_.pop_back();
      skip_to(o.name, {OKind::endif}, b, scratch_);
      return;
    }
    case OKind::endif:
      if (!top_is(FrameKind::if_)) fail(b, o.column, "o" + o.name + " endif without its if");
      stack_.pop_back();
      return;
    case OKind::break_: case OKind::continue_: {
      // The named loop, with everything opened inside it.
      std::size_t k = stack_.size();
      while (k > 0 && !(stack_[k - 1].name == o.name && stack_[k - 1].kind != FrameKind::if_ &&
                        stack_[k - 1].kind != FrameKind::call))
        --k;
      if (k == 0) fail(b, o.column, "o" + o.name + " " + kind_name(o.kind) + " outside its loop");
      stack_.resize(k);
      Frame& f = stack_.back();
      if (o.kind == OKind::break_) {
        const FrameKind fk = f.kind;
        stack_.pop_back();
        if (fk == FrameKind::while_) skip_to(o.name, {OKind::endwhile}, b, scratch_);
        else if (fk == FrameKind::repeat) skip_to(o.name, {OKind::endrepeat}, b, scratch_);
        else skip_to(o.name, {OKind::while_}, b, scratch_);
        return;
      }
      if (f.kind == FrameKind::while_) src_.seek(f.pos);
      else if (f.kind == FrameKind::repeat) {
        if (--f.remaining > 0) src_.seek(f.pos);
        else {
          stack_.pop_back();
          skip_to(o.name, {OKind::endrepeat}, b, scratch_);
        }
      } else {
        // do-while: evaluate the closing while now.
        skip_to(o.name, {OKind::while_}, b, scratch_);
        if (scratch_.o.value != 0) src_.seek(stack_.back().pos);
        else stack_.pop_back();
      }
      return;
    }
    default:
      return;
  }
}

bool ProgramReader::handle_fanuc_m98_m99(Block& b) {
  int m98 = 0, m99 = 0;
  for (const Word& w : b.words)
    if (w.letter == 'M') {
      const int t = code_tenths(w.value);
      if (t == 980) m98 = w.column;
      if (t == 990) m99 = w.column;
    }
  if (!m98 && !m99) return false;
  for (const Word& w : b.words)
    if (w.letter != 'N' && w.letter != 'P' && w.letter != 'L' && w.letter != 'M')
      fail(b, w.column, "M98/M99 with other words in the block is not supported");
  if (m98) {
    const Word* p = b.find('P');
    if (!p || p->value < 0 || p->value != std::floor(p->value) || p->value > 99999999)
      fail(b, m98, "M98 needs P with a program number");
    const Word* l = b.find('L');
    if (l && !(l->value >= 1 && l->value <= 1e9)) fail(b, l->column, "L (repeat count) must be from 1 to 1e9");
    const long long count = l ? std::llround(l->value) : 1;
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.0f", p->value);
    const LinePosition body = find_program(buf, b);
    if (static_cast<int>(stack_.size()) >= opt_.max_call_depth)
      fail(b, m98, "subprogram calls nested deeper than " + std::to_string(opt_.max_call_depth));
    stack_.push_back(Frame{FrameKind::m98, buf, src_.tell(), count, b.line});
    // Remember both where to return and where the body starts.
    stack_.push_back(Frame{FrameKind::m98, buf, body, count, b.line});
    src_.seek(body);
    return true;
  }
  // M99: end of a subprogram pass; in the main program, its end.
  if (stack_.size() < 2 || stack_.back().kind != FrameKind::m98) {
    ended_ = true;
    return true;
  }
  Frame& body = stack_.back();
  if (--body.remaining > 0) {
    src_.seek(body.pos);
    return true;
  }
  stack_.pop_back();
  const LinePosition back = stack_.back().pos;
  stack_.pop_back();
  src_.seek(back);
  return true;
}

bool ProgramReader::next(Block& b) {
  if (ended_) return false;
  std::string_view line;
  for (;;) {
    const LinePosition here = src_.tell();
    if (!read_line(line)) {
      if (!stack_.empty()) {
        const Frame& f = stack_.back();
        static const char* kNames[] = {"call", "M98 call", "while", "do", "repeat", "if"};
        const std::string what = f.kind == FrameKind::m98 ? "subprogram O" + f.name
                                 : "o" + f.name + " " + kNames[static_cast<int>(f.kind)];
        throw ParseError(SourceLocation{file_, f.line, 0, {}}, "the file ends inside " + what + " (opened at this line)");
      }
      return false;
    }
    if (opt_.block_delete) {
      std::size_t k = 0;
      while (k < line.size() && (line[k] == ' ' || line[k] == '\t')) ++k;
      if (k < line.size() && line[k] == '/') continue;
    }
    parse(line, b);
    if (b.o.kind == OKind::while_ && opt_.dialect == Dialect::rs274ngc) {
      // A while loop returns to its own line to test the condition again.
      const bool reentry = !stack_.empty() && stack_.back().kind == FrameKind::while_ && stack_.back().name == b.o.name;
      handle_oword(b);
      if (!reentry && !stack_.empty() && stack_.back().kind == FrameKind::while_ && stack_.back().name == b.o.name)
        stack_.back().pos = here;
      continue;
    }
    if (b.o.kind == OKind::program_number) {
      if (!b.words.empty()) fail(b, b.words.front().column, "words after a program number");
      if (stack_.empty() && max_line_ > 0 && !programs_.empty()) { ended_ = true; return false; }
      programs_.emplace(b.o.name, src_.tell());
      continue;
    }
    if (b.o.kind != OKind::none) {
      handle_oword(b);
      continue;
    }
    if (b.words.empty()) continue;
    if (opt_.dialect == Dialect::fanuc && handle_fanuc_m98_m99(b)) {
      if (ended_) return false;
      continue;
    }
    for (const Word& w : b.words)
      if (w.letter == 'M' && (code_tenths(w.value) == 20 || code_tenths(w.value) == 300)) ended_ = true;
    return true;
  }
}

}  // namespace cutsim::gcode
