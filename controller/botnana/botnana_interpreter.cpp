// controller layer — the Botnana Control language: outer interpreter, compiler, inner
// interpreter and the core (non-drive) words (see botnana_interpreter.hpp).
#include "controller/botnana/botnana_interpreter.hpp"

#include <algorithm>
#include <charconv>
#include <limits>
#include <utility>

#include <fmt/format.h>

namespace omnitwin::botnana {

namespace {

std::string lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) {
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  }
  return out;
}

// Decimal, `$hex` or `0xhex`, each with an optional leading '-'. nullopt when not a number
// or out of the 64-bit signed range.
std::optional<std::int64_t> parse_number(std::string_view s) {
  bool negative = false;
  if (!s.empty() && s.front() == '-') {
    negative = true;
    s.remove_prefix(1);
  }
  int base = 10;
  if (!s.empty() && s.front() == '$') {
    base = 16;
    s.remove_prefix(1);
  } else if (s.size() > 2 && s[0] == '0' && (s[1] == 'x' || s[1] == 'X')) {
    base = 16;
    s.remove_prefix(2);
  }
  if (s.empty()) return std::nullopt;
  std::uint64_t v = 0;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v, base);
  if (ec != std::errc() || end != s.data() + s.size()) return std::nullopt;
  constexpr std::uint64_t kMaxPos = static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max());
  if (negative) {
    if (v > kMaxPos + 1) return std::nullopt;
    return static_cast<std::int64_t>(0 - v);
  }
  if (v > kMaxPos) return std::nullopt;
  return static_cast<std::int64_t>(v);
}

std::int64_t wrap_add(std::int64_t a, std::int64_t b) {
  return static_cast<std::int64_t>(static_cast<std::uint64_t>(a) + static_cast<std::uint64_t>(b));
}
std::int64_t wrap_sub(std::int64_t a, std::int64_t b) {
  return static_cast<std::int64_t>(static_cast<std::uint64_t>(a) - static_cast<std::uint64_t>(b));
}
std::int64_t wrap_mul(std::int64_t a, std::int64_t b) {
  return static_cast<std::int64_t>(static_cast<std::uint64_t>(a) * static_cast<std::uint64_t>(b));
}
constexpr std::int64_t flag(bool b) { return b ? -1 : 0; }

// The words of seed 004 that are defined in the seed as Forth (the `until-…` waits); they are
// compiled at construction exactly as the seed writes them.
constexpr std::string_view kPrelude = R"(
: until-drive-on ( ch n -- )
    begin
        over over drive-on? not
    while
        pause
    repeat
    drop drop ;
: until-no-fault ( channel slave -- )
    pause pause pause pause pause pause \ the newest status word must have arrived
    begin
        over over drive-fault?
    while
        pause
    repeat
    drop drop ;
: until-target-reached ( channel slave -- )
    pause pause pause pause pause pause \ the newest status word must have arrived
    begin
        over over target-reached? not
    while
        pause
    repeat
    drop drop
;
)";

// The drives of check_script(): none (nothing runs there).
class NoDrives : public DriveAccess {
 public:
  bool has_drive(int, int) const override { return false; }
  std::optional<std::int64_t> read(int, int, std::uint16_t, std::uint8_t) override { return std::nullopt; }
  bool write(int, int, std::uint16_t, std::uint8_t, std::int64_t) override { return false; }
  void set_goal(int, int, PdsGoal) override {}
  void release_goal(int, int) override {}
  bool requests_pending(int) const override { return false; }
  std::string last_error() const override { return "a script check runs nothing"; }
};

}  // namespace

std::string Status::to_string() const {
  if (ok) return "ok";
  return fmt::format("error: `{}` at position {}: {}", word, position, message);
}

std::string Status::located(std::string_view file) const {
  if (ok) return fmt::format("{}: ok", file);
  if (line == 0) return fmt::format("{}: `{}` at position {}: {}", file, word, position, message);
  return fmt::format("{}:{}:{}: `{}`: {}", file, line, position + 1, word, message);
}

Status Interpreter::check_script(std::span<const std::string> lines) {
  NoDrives none;
  Interpreter in(none);
  in.checking_ = true;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    Status s = in.evaluate(lines[i], i + 1);
    if (!s) return s;
  }
  if (!in.compiling()) return Status{};
  Status s;
  s.ok = false;
  s.line = in.def_line_;
  s.position = in.def_position_;
  if (in.mode_ == Mode::colon) {
    s.word = ":";
    s.message = fmt::format("definition `{}` is not closed: `;` is missing before the end of the script", in.def_name_);
  } else {
    s.word = "deploy";
    s.message = "this deploy body is not closed: `;deploy` is missing before the end of the script";
  }
  return s;
}

// The core words: stack, arithmetic, comparison, memory, output, tasks.
struct CoreWords {
  using In = Interpreter;
  using T = Interpreter::Task;
  using R = Interpreter::PrimResult;

  static bool need(T& t, std::size_t n) {
    if (t.ds.size() >= n) return true;
    t.error = "stack underflow";
    return false;
  }
  static bool push(T& t, std::int64_t v) {
    if (t.ds.size() >= In::kMaxDataStack) {
      t.error = "stack overflow";
      return false;
    }
    t.ds.push_back(v);
    return true;
  }
  static std::int64_t pop(T& t) {
    const std::int64_t v = t.ds.back();
    t.ds.pop_back();
    return v;
  }
  static R res(bool ok) { return ok ? R::ok : R::error; }

  // Binary operators ( a b -- c ), selected by aux.
  enum class Bin : std::int64_t { add, sub, mul, div, mod, min, max, and_, or_, xor_, eq, ne, lt, gt, le, ge };
  static R binary(In&, T& t, std::int64_t aux) {
    if (!need(t, 2)) return R::error;
    const std::int64_t b = pop(t);
    const std::int64_t a = pop(t);
    std::int64_t c = 0;
    switch (static_cast<Bin>(aux)) {
      case Bin::add: c = wrap_add(a, b); break;
      case Bin::sub: c = wrap_sub(a, b); break;
      case Bin::mul: c = wrap_mul(a, b); break;
      case Bin::div:
      case Bin::mod:
        if (b == 0) {
          t.error = "division by zero";
          return R::error;
        }
        if (b == -1) {  // the one overflowing case (min / -1) wraps
          c = static_cast<Bin>(aux) == Bin::div ? wrap_sub(0, a) : 0;
        } else {
          c = static_cast<Bin>(aux) == Bin::div ? a / b : a % b;
        }
        break;
      case Bin::min: c = std::min(a, b); break;
      case Bin::max: c = std::max(a, b); break;
      case Bin::and_: c = a & b; break;
      case Bin::or_: c = a | b; break;
      case Bin::xor_: c = a ^ b; break;
      case Bin::eq: c = flag(a == b); break;
      case Bin::ne: c = flag(a != b); break;
      case Bin::lt: c = flag(a < b); break;
      case Bin::gt: c = flag(a > b); break;
      case Bin::le: c = flag(a <= b); break;
      case Bin::ge: c = flag(a >= b); break;
    }
    t.ds.push_back(c);
    return R::ok;
  }

  // Unary operators ( a -- b ).
  enum class Un : std::int64_t { negate, abs, invert, zero_eq, zero_lt, inc, dec };
  static R unary(In&, T& t, std::int64_t aux) {
    if (!need(t, 1)) return R::error;
    std::int64_t& a = t.ds.back();
    switch (static_cast<Un>(aux)) {
      case Un::negate: a = wrap_sub(0, a); break;
      case Un::abs: a = a < 0 ? wrap_sub(0, a) : a; break;
      case Un::invert: a = ~a; break;
      case Un::zero_eq: a = flag(a == 0); break;
      case Un::zero_lt: a = flag(a < 0); break;
      case Un::inc: a = wrap_add(a, 1); break;
      case Un::dec: a = wrap_sub(a, 1); break;
    }
    return R::ok;
  }

  // Stack shuffles, selected by aux.
  enum class Sh : std::int64_t { dup, drop, swap, over, rot, mrot, nip, tuck, two_dup, two_drop, pick };
  static R shuffle(In&, T& t, std::int64_t aux) {
    auto& s = t.ds;
    const std::size_t n = s.size();
    switch (static_cast<Sh>(aux)) {
      case Sh::dup:
        if (!need(t, 1)) return R::error;
        return res(push(t, s[n - 1]));
      case Sh::drop:
        if (!need(t, 1)) return R::error;
        s.pop_back();
        return R::ok;
      case Sh::swap:
        if (!need(t, 2)) return R::error;
        std::swap(s[n - 1], s[n - 2]);
        return R::ok;
      case Sh::over:
        if (!need(t, 2)) return R::error;
        return res(push(t, s[n - 2]));
      case Sh::rot:  // ( a b c -- b c a )
        if (!need(t, 3)) return R::error;
        std::rotate(s.end() - 3, s.end() - 2, s.end());
        return R::ok;
      case Sh::mrot:  // ( a b c -- c a b )
        if (!need(t, 3)) return R::error;
        std::rotate(s.end() - 3, s.end() - 1, s.end());
        return R::ok;
      case Sh::nip:
        if (!need(t, 2)) return R::error;
        s.erase(s.end() - 2);
        return R::ok;
      case Sh::tuck:  // ( a b -- b a b )
        if (!need(t, 2)) return R::error;
        if (!push(t, s[n - 1])) return R::error;
        std::swap(s[n - 1], s[n - 2]);
        return R::ok;
      case Sh::two_dup:
        if (!need(t, 2)) return R::error;
        if (!push(t, s[n - 2])) return R::error;
        return res(push(t, s[n - 1]));
      case Sh::two_drop:
        if (!need(t, 2)) return R::error;
        s.resize(n - 2);
        return R::ok;
      case Sh::pick: {  // ( xu … x0 u -- xu … x0 xu )
        if (!need(t, 1)) return R::error;
        const std::int64_t u = s.back();
        if (u < 0 || static_cast<std::size_t>(u) + 2 > n) {
          t.error = "stack underflow";
          return R::error;
        }
        s.back() = s[n - 2 - static_cast<std::size_t>(u)];
        return R::ok;
      }
    }
    return R::ok;
  }

  static R constant_value(In&, T& t, std::int64_t aux) { return res(push(t, aux)); }

  // Memory: aux 0 `!` ( x addr -- ), 1 `@` ( addr -- x ), 2 `+!` ( n addr -- ).
  static R memory(In& in, T& t, std::int64_t aux) {
    const std::size_t args = aux == 1 ? 1 : 2;
    if (!need(t, args)) return R::error;
    const std::int64_t addr = pop(t);
    if (addr < 0 || static_cast<std::size_t>(addr) >= in.cells_.size()) {
      t.error = fmt::format("invalid address {}", addr);
      return R::error;
    }
    std::int64_t& cell = in.cells_[static_cast<std::size_t>(addr)];
    if (aux == 1) {
      t.ds.push_back(cell);
    } else if (aux == 0) {
      cell = pop(t);
    } else {
      cell = wrap_add(cell, pop(t));
    }
    return R::ok;
  }

  // Output: aux 0 `.`, 1 `.s`, 2 `cr`, 3 `emit`.
  static R output(In& in, T& t, std::int64_t aux) {
    switch (aux) {
      case 0:
        if (!need(t, 1)) return R::error;
        in.print(fmt::format("{} ", pop(t)));
        return R::ok;
      case 1: {
        std::string s = fmt::format("<{}> ", t.ds.size());
        for (std::int64_t v : t.ds) s += fmt::format("{} ", v);
        in.print(s);
        return R::ok;
      }
      case 2:
        in.print("\n");
        return R::ok;
      default: {
        if (!need(t, 1)) return R::error;
        const char c = static_cast<char>(pop(t) & 0xFF);
        in.print(std::string_view(&c, 1));
        return R::ok;
      }
    }
  }

  // Loop indices: aux 0 `i`, 1 `j`.
  static R loop_index(In&, T& t, std::int64_t aux) {
    const std::size_t depth = static_cast<std::size_t>(aux) + 1;
    if (t.ls.size() < depth) {
      t.error = "no loop to take the index of";
      return R::error;
    }
    return res(push(t, t.ls[t.ls.size() - depth].index));
  }

  static R pause(In&, T&, std::int64_t) { return R::yield; }

  static R ms(In& in, T& t, std::int64_t) {
    if (!need(t, 1)) return R::error;
    const std::int64_t n = pop(t);
    if (n <= 0) return R::ok;
    const std::int64_t ns = n > std::numeric_limits<std::int64_t>::max() / 1'000'000
                                ? std::numeric_limits<std::int64_t>::max()
                                : n * 1'000'000;
    const std::int64_t cycles = ns / in.period_ns_ + (ns % in.period_ns_ != 0 ? 1 : 0);
    t.wait_cycles = cycles - 1;  // the yield itself is the first cycle
    return R::yield;
  }

  static void install(In& in) {
    const std::pair<const char*, Bin> bins[] = {
        {"+", Bin::add},  {"-", Bin::sub},    {"*", Bin::mul},   {"/", Bin::div},
        {"mod", Bin::mod}, {"min", Bin::min}, {"max", Bin::max}, {"and", Bin::and_},
        {"or", Bin::or_},  {"xor", Bin::xor_}, {"=", Bin::eq},   {"<>", Bin::ne},
        {"<", Bin::lt},    {">", Bin::gt},    {"<=", Bin::le},   {">=", Bin::ge}};
    for (const auto& [name, op] : bins) in.add_prim(name, binary, static_cast<std::int64_t>(op));
    const std::pair<const char*, Un> uns[] = {
        {"negate", Un::negate}, {"abs", Un::abs}, {"invert", Un::invert}, {"0=", Un::zero_eq},
        {"not", Un::zero_eq},   {"0<", Un::zero_lt}, {"1+", Un::inc},     {"1-", Un::dec}};
    for (const auto& [name, op] : uns) in.add_prim(name, unary, static_cast<std::int64_t>(op));
    const std::pair<const char*, Sh> shs[] = {
        {"dup", Sh::dup},   {"drop", Sh::drop},      {"swap", Sh::swap},        {"over", Sh::over},
        {"rot", Sh::rot},   {"-rot", Sh::mrot},      {"nip", Sh::nip},          {"tuck", Sh::tuck},
        {"2dup", Sh::two_dup}, {"2drop", Sh::two_drop}, {"pick", Sh::pick}};
    for (const auto& [name, op] : shs) in.add_prim(name, shuffle, static_cast<std::int64_t>(op));
    in.add_prim("true", constant_value, -1);
    in.add_prim("false", constant_value, 0);
    in.add_prim("!", memory, 0);
    in.add_prim("@", memory, 1);
    in.add_prim("+!", memory, 2);
    in.add_prim(".", output, 0);
    in.add_prim(".s", output, 1);
    in.add_prim("cr", output, 2);
    in.add_prim("emit", output, 3);
    in.add_prim("i", loop_index, 0, /*compile_only=*/true);
    in.add_prim("j", loop_index, 1, /*compile_only=*/true);
    in.add_prim("pause", pause, 0, false, /*background_only=*/true);
    in.add_prim("ms", ms, 0, false, /*background_only=*/true);
  }
};

Interpreter::Interpreter(DriveAccess& drives, Output output)
    : drives_(drives), output_(std::move(output)) {
  fg_.ds.reserve(kMaxDataStack);
  fg_.rs.reserve(kMaxReturnStack);
  fg_.ls.reserve(kMaxLoopStack);
  fg_.name = "foreground";
  install_core_words();
  install_drive_words();
  const Status s = load_prelude(kPrelude);
  (void)s;  // the prelude is fixed source; the tests check that its words exist
}

Interpreter::~Interpreter() = default;

void Interpreter::install_core_words() { CoreWords::install(*this); }

Status Interpreter::load_prelude(std::string_view source) {
  std::size_t begin = 0;
  Status last;
  while (begin < source.size()) {
    std::size_t end = source.find('\n', begin);
    if (end == std::string_view::npos) end = source.size();
    last = evaluate(source.substr(begin, end - begin));
    if (!last) return last;
    begin = end + 1;
  }
  // The seed's waits are background-only words.
  for (const char* name : {"until-drive-on", "until-no-fault", "until-target-reached"}) {
    const int w = find(name);
    if (w >= 0) words_[static_cast<std::size_t>(w)].background_only = true;
  }
  return last;
}

int Interpreter::add_word(Word w) {
  w.name = lower(w.name);
  words_.push_back(std::move(w));
  const int id = static_cast<int>(words_.size() - 1);
  index_[words_.back().name] = id;
  return id;
}

int Interpreter::add_prim(std::string_view name, PrimFn fn, std::int64_t aux, bool compile_only,
                          bool background_only) {
  prims_.push_back(Prim{fn, aux});
  Word w;
  w.name = std::string(name);
  w.kind = Kind::prim;
  w.value = static_cast<std::int64_t>(prims_.size() - 1);
  w.compile_only = compile_only;
  w.background_only = background_only;
  return add_word(std::move(w));
}

int Interpreter::find(std::string_view name) const {
  const auto it = index_.find(lower(name));
  return it == index_.end() ? -1 : it->second;
}

bool Interpreter::defined(std::string_view name) const { return find(name) >= 0; }

std::span<const std::int64_t> Interpreter::stack() const noexcept { return fg_.ds; }

void Interpreter::set_cycle_period_ns(std::int64_t period_ns) noexcept {
  if (period_ns > 0) period_ns_ = period_ns;
}

void Interpreter::kill_tasks() noexcept { tasks_.clear(); }

bool Interpreter::homed(int slave, int ch) const {
  const std::int64_t key = (static_cast<std::int64_t>(slave) << 16) | ch;
  return std::find(homed_.begin(), homed_.end(), key) != homed_.end();
}

Status Interpreter::fail(const Token& tok, std::string message) {
  Status s;
  s.ok = false;
  s.word = std::string(tok.text);
  s.line = line_no_;
  s.position = tok.position;
  s.message = std::move(message);
  reset_after_error();
  return s;
}

void Interpreter::reset_after_error() {
  fg_.ds.clear();
  fg_.rs.clear();
  fg_.ls.clear();
  fg_.error.clear();
  if (mode_ != Mode::interpret) {
    code_.resize(def_start_);
    code_words_.resize(def_start_);
    mode_ = Mode::interpret;
  }
  cs_.clear();
}

Status Interpreter::evaluate(std::string_view line, std::size_t line_no) {
  line_no_ = line_no;
  Lexer lex(line);
  while (const auto tok = lex.next()) {
    Status s = interpret_token(lex, *tok);
    if (!s) return s;
  }
  return Status{};
}

Status Interpreter::compile_control(std::string_view w, const Token& tok) {
  const auto here = [this] { return code_.size(); };
  const auto pos = static_cast<std::uint32_t>(tok.position);
  const auto pop_kind = [this](std::initializer_list<Ctl> kinds, Control& out) {
    if (cs_.empty()) return false;
    if (std::find(kinds.begin(), kinds.end(), cs_.back().kind) == kinds.end()) return false;
    out = cs_.back();
    cs_.pop_back();
    return true;
  };
  Control c{};
  if (w == "if") {
    cs_.push_back({Ctl::if_, here()});
    emit({Op::branch0, 0, pos}, tok.text);
  } else if (w == "else") {
    if (!pop_kind({Ctl::if_}, c)) return fail(tok, "`else` without `if`");
    cs_.push_back({Ctl::else_, here()});
    emit({Op::branch, 0, pos}, tok.text);
    code_[c.at].arg = static_cast<std::int64_t>(here());
  } else if (w == "then") {
    if (!pop_kind({Ctl::if_, Ctl::else_}, c)) return fail(tok, "`then` without `if`");
    code_[c.at].arg = static_cast<std::int64_t>(here());
  } else if (w == "begin") {
    cs_.push_back({Ctl::begin, here()});
  } else if (w == "until" || w == "again") {
    if (!pop_kind({Ctl::begin}, c)) return fail(tok, fmt::format("`{}` without `begin`", w));
    emit({w == "until" ? Op::branch0 : Op::branch, static_cast<std::int64_t>(c.at), pos}, tok.text);
  } else if (w == "while") {
    if (cs_.empty() || cs_.back().kind != Ctl::begin) return fail(tok, "`while` without `begin`");
    cs_.push_back({Ctl::while_, here()});
    emit({Op::branch0, 0, pos}, tok.text);
  } else if (w == "repeat") {
    Control b{};
    if (!pop_kind({Ctl::while_}, c) || !pop_kind({Ctl::begin}, b)) {
      return fail(tok, "`repeat` without `begin … while`");
    }
    emit({Op::branch, static_cast<std::int64_t>(b.at), pos}, tok.text);
    code_[c.at].arg = static_cast<std::int64_t>(here());
  } else if (w == "do") {
    emit({Op::do_init, 0, pos}, tok.text);
    cs_.push_back({Ctl::do_, here()});
  } else {  // loop, +loop
    if (!pop_kind({Ctl::do_}, c)) return fail(tok, fmt::format("`{}` without `do`", w));
    emit({w == "loop" ? Op::loop : Op::plus_loop, static_cast<std::int64_t>(c.at), pos}, tok.text);
  }
  return Status{};
}

Status Interpreter::interpret_token(Lexer& lex, const Token& tok) {
  const std::string w = lower(tok.text);
  const bool comp = mode_ != Mode::interpret;
  const auto pos = static_cast<std::uint32_t>(tok.position);

  // Comments and strings.
  if (w == "\\") {
    lex.skip_line();
    return Status{};
  }
  if (w == "(") {
    if (!lex.until(')')) lex.skip_line();  // an unclosed comment runs to the end of the line
    return Status{};
  }
  if (w == ".\"") {
    const auto text = lex.until('"');
    if (!text) return fail(tok, "missing closing \" of the string");
    if (comp) {
      strings_.emplace_back(text->text);
      emit({Op::dot_str, static_cast<std::int64_t>(strings_.size() - 1), pos}, tok.text);
    } else if (!checking_) {
      print(text->text);
    }
    return Status{};
  }

  // Defining words.
  if (w == ":") {
    if (comp) return fail(tok, "`:` inside a definition (definitions do not nest)");
    const auto name = lex.next();
    if (!name) return fail(tok, "missing name after `:`");
    mode_ = Mode::colon;
    def_name_ = std::string(name->text);
    def_start_ = code_.size();
    def_line_ = line_no_;
    def_position_ = tok.position;
    cs_.clear();
    return Status{};
  }
  if (w == ";") {
    if (mode_ == Mode::interpret) return fail(tok, "compile-only word outside a definition");
    if (mode_ == Mode::deploy) return fail(tok, "`;` inside `deploy … ;deploy`");
    if (!cs_.empty()) return fail(tok, "unbalanced control structure (missing then/until/repeat/loop)");
    emit({Op::exit, 0, pos}, tok.text);
    Word word;
    word.name = def_name_;
    word.kind = Kind::colon;
    word.value = static_cast<std::int64_t>(def_start_);
    add_word(std::move(word));
    mode_ = Mode::interpret;
    return Status{};
  }
  if (w == "deploy") {
    if (comp) return fail(tok, "`deploy` inside a definition");
    mode_ = Mode::deploy;
    def_start_ = code_.size();
    def_line_ = line_no_;
    def_position_ = tok.position;
    cs_.clear();
    return Status{};
  }
  if (w == ";deploy") {
    if (mode_ != Mode::deploy) return fail(tok, "`;deploy` without `deploy`");
    if (!cs_.empty()) return fail(tok, "unbalanced control structure (missing then/until/repeat/loop)");
    emit({Op::exit, 0, pos}, tok.text);
    mode_ = Mode::interpret;
    if (checking_) return Status{};  // compiled, never run
    auto task = std::make_unique<Task>();
    task->ds.reserve(kMaxDataStack);
    task->rs.reserve(kMaxReturnStack);
    task->ls.reserve(kMaxLoopStack);
    task->background = true;
    task->ip = def_start_;
    task->rs.push_back({kNoReturn, -1, 0});
    task->name = fmt::format("task{}", ++deployed_);
    tasks_.push_back(std::move(task));
    return Status{};
  }
  if (w == "variable" || w == "constant") {
    if (comp) return fail(tok, fmt::format("`{}` inside a definition", w));
    const auto name = lex.next();
    if (!name) return fail(tok, fmt::format("missing name after `{}`", w));
    Word word;
    word.name = std::string(name->text);
    if (w == "variable") {
      cells_.push_back(0);
      word.kind = Kind::variable;
      word.value = static_cast<std::int64_t>(cells_.size() - 1);
    } else if (checking_) {
      word.kind = Kind::constant;  // its value is known only when it runs
      word.value = 0;
    } else {
      if (fg_.ds.empty()) return fail(tok, "stack underflow");
      word.kind = Kind::constant;
      word.value = fg_.ds.back();
      fg_.ds.pop_back();
    }
    add_word(std::move(word));
    return Status{};
  }

  // Control structures and exit.
  static constexpr std::string_view kControl[] = {"if",    "else", "then", "begin", "until", "again",
                                                  "while", "repeat", "do", "loop", "+loop"};
  if (std::find(std::begin(kControl), std::end(kControl), w) != std::end(kControl)) {
    if (!comp) return fail(tok, "compile-only word outside a definition");
    return compile_control(w, tok);
  }
  if (w == "exit") {
    if (!comp) return fail(tok, "compile-only word outside a definition");
    emit({Op::exit, 0, pos}, tok.text);
    return Status{};
  }

  // Dictionary words, then numbers.
  const int id = find(w);
  if (id >= 0) {
    const Word& word = words_[static_cast<std::size_t>(id)];
    if (!comp) return execute_word(id, tok);
    switch (word.kind) {
      case Kind::constant:
      case Kind::variable: emit({Op::lit, word.value, pos}, tok.text); break;
      case Kind::prim: emit({Op::prim, id, pos}, tok.text); break;
      case Kind::colon: emit({Op::call, id, pos}, tok.text); break;
    }
    return Status{};
  }
  if (const auto n = parse_number(tok.text)) {
    if (comp) {
      emit({Op::lit, *n, pos}, tok.text);
    } else if (!checking_) {
      if (fg_.ds.size() >= kMaxDataStack) return fail(tok, "stack overflow");
      fg_.ds.push_back(*n);
    }
    return Status{};
  }
  return fail(tok, "unknown word");
}

Status Interpreter::execute_word(int id, const Token& tok) {
  const Word& word = words_[static_cast<std::size_t>(id)];
  if (word.compile_only) return fail(tok, "compile-only word outside a definition");
  if (word.background_only) {
    return fail(tok, "waits for master cycles (pause): only in a background task (deploy … ;deploy)");
  }
  if (checking_) return Status{};
  switch (word.kind) {
    case Kind::constant:
    case Kind::variable:
      if (fg_.ds.size() >= kMaxDataStack) return fail(tok, "stack overflow");
      fg_.ds.push_back(word.value);
      return Status{};
    case Kind::prim: {
      const Prim& p = prims_[static_cast<std::size_t>(word.value)];
      const PrimResult r = p.fn(*this, fg_, p.aux);
      if (r == PrimResult::error) return fail(tok, fg_.error);
      if (r != PrimResult::ok) return fail(tok, "pause outside a background task");
      return Status{};
    }
    case Kind::colon: break;
  }
  fg_.rs.clear();
  fg_.ls.clear();
  fg_.rs.push_back({kNoReturn, -1, 0});
  fg_.ip = static_cast<std::size_t>(word.value);
  fg_.word = id;
  std::size_t at = 0;
  const RunResult r = run(fg_, budget_, at);
  if (r == RunResult::done) return Status{};
  const Instr& in = code_[at];
  std::string inner;
  if (in.op == Op::prim || in.op == Op::call) inner = words_[static_cast<std::size_t>(in.arg)].name;
  const std::string where =
      fg_.word >= 0 ? words_[static_cast<std::size_t>(fg_.word)].name : std::string(tok.text);
  std::string msg = r == RunResult::yielded ? "pause outside a background task" : fg_.error;
  if (!inner.empty()) {
    msg += fmt::format(" (in `{}`, called from `{}` at position {})", inner, where, in.position);
  } else {
    msg += fmt::format(" (in `{}` at position {})", where, in.position);
  }
  return fail(tok, msg);
}

Interpreter::RunResult Interpreter::run(Task& t, std::uint64_t budget, std::size_t& failed_at) {
  for (std::uint64_t steps = 0;; ++steps) {
    const std::size_t at = t.ip;
    if (steps >= budget) {
      failed_at = at;
      t.error = fmt::format("ran {} instructions without pause (runaway loop?)", budget);
      return RunResult::error;
    }
    const Instr in = code_[at];
    ++t.ip;
    switch (in.op) {
      case Op::lit:
        if (t.ds.size() >= kMaxDataStack) {
          failed_at = at;
          t.error = "stack overflow";
          return RunResult::error;
        }
        t.ds.push_back(in.arg);
        break;
      case Op::prim: {
        const Word& w = words_[static_cast<std::size_t>(in.arg)];
        if (w.background_only && !t.background) {
          failed_at = at;
          t.error = "waits for master cycles (pause): only in a background task (deploy … ;deploy)";
          return RunResult::error;
        }
        const Prim& p = prims_[static_cast<std::size_t>(w.value)];
        switch (p.fn(*this, t, p.aux)) {
          case PrimResult::ok: break;
          case PrimResult::yield: return RunResult::yielded;
          case PrimResult::retry: t.ip = at; return RunResult::yielded;
          case PrimResult::error: failed_at = at; return RunResult::error;
        }
        break;
      }
      case Op::call: {
        const Word& w = words_[static_cast<std::size_t>(in.arg)];
        if (w.background_only && !t.background) {
          failed_at = at;
          t.error = "waits for master cycles (pause): only in a background task (deploy … ;deploy)";
          return RunResult::error;
        }
        if (t.rs.size() >= kMaxReturnStack) {
          failed_at = at;
          t.error = "return stack overflow";
          return RunResult::error;
        }
        t.rs.push_back({t.ip, t.word, t.ls.size()});
        t.ip = static_cast<std::size_t>(w.value);
        t.word = static_cast<int>(in.arg);
        break;
      }
      case Op::exit: {
        const Frame f = t.rs.back();
        t.rs.pop_back();
        t.ls.resize(std::min(t.ls.size(), f.loops));
        if (f.return_ip == kNoReturn) return RunResult::done;
        t.ip = f.return_ip;
        t.word = f.word;
        break;
      }
      case Op::branch: t.ip = static_cast<std::size_t>(in.arg); break;
      case Op::branch0:
        if (t.ds.empty()) {
          failed_at = at;
          t.error = "stack underflow";
          return RunResult::error;
        }
        if (t.ds.back() == 0) t.ip = static_cast<std::size_t>(in.arg);
        t.ds.pop_back();
        break;
      case Op::do_init: {  // ( limit start -- )
        if (t.ds.size() < 2) {
          failed_at = at;
          t.error = "stack underflow";
          return RunResult::error;
        }
        if (t.ls.size() >= kMaxLoopStack) {
          failed_at = at;
          t.error = "loop stack overflow";
          return RunResult::error;
        }
        const std::int64_t start = t.ds.back();
        t.ds.pop_back();
        const std::int64_t limit = t.ds.back();
        t.ds.pop_back();
        t.ls.push_back({start, limit});
        break;
      }
      case Op::loop:
      case Op::plus_loop: {
        if (t.ls.empty()) {
          failed_at = at;
          t.error = "loop without do";
          return RunResult::error;
        }
        std::int64_t step = 1;
        if (in.op == Op::plus_loop) {
          if (t.ds.empty()) {
            failed_at = at;
            t.error = "stack underflow";
            return RunResult::error;
          }
          step = t.ds.back();
          t.ds.pop_back();
        }
        Loop& l = t.ls.back();
        // Forth's rule: the loop ends when the index crosses the boundary limit-1 | limit.
        const std::int64_t before = wrap_sub(l.index, l.limit);
        l.index = wrap_add(l.index, step);
        const std::int64_t after = wrap_sub(l.index, l.limit);
        const bool crossed = step >= 0 ? (before < 0 && after >= 0) : (before >= 0 && after < 0);
        if (crossed) {
          t.ls.pop_back();
        } else {
          t.ip = static_cast<std::size_t>(in.arg);
        }
        break;
      }
      case Op::dot_str: print(strings_[static_cast<std::size_t>(in.arg)]); break;
    }
  }
}

std::size_t Interpreter::step_tasks() {
  for (std::size_t k = 0; k < tasks_.size();) {
    Task& t = *tasks_[k];
    if (t.wait_cycles > 0) {
      --t.wait_cycles;
      ++k;
      continue;
    }
    std::size_t at = 0;
    const RunResult r = run(t, budget_, at);
    if (r == RunResult::yielded) {
      ++k;
      continue;
    }
    if (r == RunResult::error) {
      const Instr& in = code_[at];
      Status s;
      s.ok = false;
      s.word = in.op == Op::prim || in.op == Op::call ? words_[static_cast<std::size_t>(in.arg)].name : code_words_[at];
      s.line = in.line;
      s.position = in.position;
      s.message = t.error;
      if (t.word >= 0) s.message += fmt::format(" (in `{}`)", words_[static_cast<std::size_t>(t.word)].name);
      s.message += fmt::format(" — {} ended", t.name);
      print(s.to_string() + "\n");
      last_task_error_ = std::move(s);
    }
    tasks_.erase(tasks_.begin() + static_cast<std::ptrdiff_t>(k));
  }
  return tasks_.size();
}

}  // namespace omnitwin::botnana
