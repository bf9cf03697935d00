// controller layer — the Botnana Control word set (seed 004) as a small Forth-like language
// (docs/botnana.md).
//
// The outer interpreter reads a line word by word (botnana_lexer.hpp): numbers go on the
// data stack, words run, or — inside `: name … ;` and `deploy … ;deploy` — are compiled into
// a threaded code (one instruction per word: literal, primitive, call, branches, loop
// control), never kept as text. Background tasks (`deploy`) are cooperative: each has its
// own data, return and loop stacks and runs until its next `pause` every time step_tasks()
// is called, which the master calls once per cycle; the `until-…` words and `ms` wait there.
// Words that only make sense in a background task (pause, ms, until-…) are errors in the
// foreground, where nothing may wait.
// Drives are reached only through DriveAccess (drive_access.hpp); every drive word of seed
// 004 maps onto one of its calls with the CiA 402 object the seed names
// (botnana_drive_words.cpp).
// Errors are statuses, never exceptions: an error in the foreground names the word, its
// byte offset in the line (and the line's number, when evaluate() was given one), empties the data stack and drops a definition being compiled,
// after which the interpreter is usable again; an error in a background task ends that task
// and is kept in last_task_error(), naming the word it stopped at (every instruction keeps
// its source word, line and position). check_script() finds a script's bad input (unknown words,
// unbalanced control structures, a definition left open at its end, …) before any of it
// runs, on a dictionary of its own. Allocation happens while compiling and deploying; running
// compiled code allocates only when stacks first grow (reserved at construction).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "controller/botnana/botnana_lexer.hpp"
#include "controller/botnana/drive_access.hpp"

namespace omnitwin::botnana {

// The result of evaluate() and of a background task.
struct Status {
  bool ok = true;
  std::string word;          // the word that failed ("" when ok)
  std::size_t line = 0;      // the 1-based number of its line, as given to evaluate() (0: not known)
  std::size_t position = 0;  // its byte offset in the line (or in the line it was compiled from)
  std::string message;       // what went wrong, e.g. "stack underflow"
  explicit operator bool() const noexcept { return ok; }
  // "ok", or "error: `word` at position P: message".
  std::string to_string() const;
  // "FILE:LINE:COLUMN: `word`: message" (column = position + 1); without a line number
  // "FILE: `word` at position P: message". No "error:" of its own: the program's log line
  // that prints it says that (omni-master printed "error: FILE:…: error: …").
  std::string located(std::string_view file) const;
};

class Interpreter {
 public:
  using Output = std::function<void(std::string_view)>;
  static constexpr std::size_t kMaxDataStack = 1024;
  static constexpr std::size_t kMaxReturnStack = 256;
  static constexpr std::size_t kMaxLoopStack = 64;
  // Instructions one evaluate() or one task step may run before it is stopped as a runaway
  // (default; see set_step_budget).
  static constexpr std::uint64_t kStepBudget = 10'000'000;

  // `drives` must outlive the interpreter. `output` receives everything `.`, `.s`, `cr`,
  // `emit`, `."` print (nothing is printed when it is empty).
  explicit Interpreter(DriveAccess& drives, Output output = {});
  ~Interpreter();
  Interpreter(const Interpreter&) = delete;
  Interpreter& operator=(const Interpreter&) = delete;

  // Interprets one line of source; `line_no` (1-based, 0 = none) is the line's number in its
  // file, which statuses report. A definition or deploy body may span several lines: the
  // compiler state carries over to the next call. Never throws; see the header comment for
  // what an error leaves behind.
  Status evaluate(std::string_view line, std::size_t line_no = 0);
  // Checks a script (line 1 first) without running any of it, on a fresh dictionary: every
  // word is known (built in, or defined earlier in the script by `:`, `variable`,
  // `constant`), control structures balance, compile-only words and waits stand where they
  // may, strings are closed, and no `: …` or `deploy …` is left open at the end (reported at
  // its `:` or `deploy`). The first problem found, with its line; ok otherwise.
  static Status check_script(std::span<const std::string> lines);
  // Runs every deployed background task until its next `pause` (or its end, or an error),
  // in the order they were deployed; finished tasks are removed. Call once per master
  // cycle. Returns the number of tasks still running.
  std::size_t step_tasks();
  std::size_t tasks_running() const noexcept { return tasks_.size(); }
  // Ends every background task at once (nothing else is undone).
  void kill_tasks() noexcept;
  // The error that ended the last failing background task (ok when none has failed).
  const Status& last_task_error() const noexcept { return last_task_error_; }

  // The master cycle period that `ms` counts in [ns] (> 0; default 1 ms).
  void set_cycle_period_ns(std::int64_t period_ns) noexcept;
  std::int64_t cycle_period_ns() const noexcept { return period_ns_; }

  // The runaway limit: instructions per evaluate() word or per task step (>= 1).
  void set_step_budget(std::uint64_t instructions) noexcept { budget_ = instructions > 0 ? instructions : 1; }
  void set_output(Output output) { output_ = std::move(output); }
  // The foreground data stack, bottom first.
  std::span<const std::int64_t> stack() const noexcept;
  // True while a `: … ;` or `deploy … ;deploy` body is being compiled.
  bool compiling() const noexcept { return mode_ != Mode::interpret; }
  // True when `name` is a word of the dictionary (case-insensitive).
  bool defined(std::string_view name) const;
  // The homing record of +drive-homed/-drive-homed kept here when the master keeps none
  // (DriveAccess::homed; seed 004 calls it a record the master provides, not a drive object).
  bool homed(int slave, int ch) const;

 private:
  friend struct CoreWords;
  friend struct DriveWords;

  enum class Op : std::uint8_t { lit, prim, call, branch, branch0, do_init, loop, plus_loop, dot_str, exit };
  struct Instr {
    Op op;
    std::int64_t arg;
    std::uint32_t position;  // byte offset of the source word (error reports)
    std::uint32_t line = 0;  // and its line's number as given to evaluate() (0: none)
  };
  struct Frame {
    std::size_t return_ip;  // kNoReturn for the outermost call
    int word;               // the word whose code is running after the return
    std::size_t loops;      // loop stack depth at the call
  };
  struct Loop {
    std::int64_t index, limit;
  };
  struct Task {
    std::vector<std::int64_t> ds;
    std::vector<Frame> rs;
    std::vector<Loop> ls;
    std::size_t ip = 0;
    int word = -1;                // the colon word running (-1: top level / deploy body)
    bool background = false;
    std::int64_t wait_cycles = 0;  // `ms`: cycles still to skip
    std::string name;
    std::string error;            // detail of the last PrimResult::error
  };
  enum class PrimResult : std::uint8_t { ok, yield, retry, error };
  using PrimFn = PrimResult (*)(Interpreter&, Task&, std::int64_t aux);
  struct Prim {
    PrimFn fn;
    std::int64_t aux;
  };
  enum class Kind : std::uint8_t { prim, colon, constant, variable };
  struct Word {
    std::string name;
    Kind kind;
    std::int64_t value;          // prim index, code start, constant value or cell address
    bool compile_only = false;   // control words: only inside a definition
    bool background_only = false;  // waits (pause, ms, until-…): only in a background task
  };
  enum class Mode : std::uint8_t { interpret, colon, deploy };
  enum class Ctl : std::uint8_t { if_, else_, begin, while_, do_ };
  struct Control {
    Ctl kind;
    std::size_t at;
  };
  enum class RunResult : std::uint8_t { done, yielded, error };
  static constexpr std::size_t kNoReturn = static_cast<std::size_t>(-1);

  int add_prim(std::string_view name, PrimFn fn, std::int64_t aux = 0, bool compile_only = false,
               bool background_only = false);
  int add_word(Word w);
  int find(std::string_view name) const;  // -1 when unknown
  void install_core_words();
  void install_drive_words();
  Status load_prelude(std::string_view source);
  Status interpret_token(Lexer& lex, const Token& tok);
  Status compile_control(std::string_view w, const Token& tok);
  Status execute_word(int word, const Token& tok);
  RunResult run(Task& t, std::uint64_t budget, std::size_t& failed_at);
  Status fail(const Token& tok, std::string message);
  void reset_after_error();
  // Appends an instruction compiled from source word `word` of the line being read.
  void emit(Instr in, std::string_view word) {
    in.line = static_cast<std::uint32_t>(line_no_);
    code_.push_back(in);
    code_words_.emplace_back(word);
  }
  void print(std::string_view s) {
    if (output_) output_(s);
  }

  DriveAccess& drives_;
  Output output_;
  std::int64_t period_ns_ = 1'000'000;
  std::uint64_t budget_ = kStepBudget;
  std::vector<Word> words_;
  std::unordered_map<std::string, int> index_;
  std::vector<Prim> prims_;
  std::vector<Instr> code_;
  std::vector<std::string> code_words_;  // the source word of each instruction (error reports)
  std::vector<std::string> strings_;
  std::vector<std::int64_t> cells_;
  Task fg_;
  std::vector<std::unique_ptr<Task>> tasks_;
  Status last_task_error_;
  std::size_t deployed_ = 0;
  // compiler state
  Mode mode_ = Mode::interpret;
  bool checking_ = false;       // check_script(): compile, look words up, run nothing
  std::size_t line_no_ = 0;     // the line evaluate() is reading
  std::string def_name_;
  std::size_t def_start_ = 0;
  std::size_t def_line_ = 0, def_position_ = 0;  // where the open `:` or `deploy` stands
  std::vector<Control> cs_;
  // drive-side records
  std::vector<std::int64_t> homed_;     // (slave << 16 | ch) of axes marked homed
  std::vector<int> request_slaves_;     // slaves SDO-written to (until-no-requests)
};

}  // namespace omnitwin::botnana
