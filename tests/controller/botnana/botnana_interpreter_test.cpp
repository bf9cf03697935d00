// Tests controller/botnana/botnana_interpreter: the language. Numbers (decimal, $hex, 0x,
// negative), every stack and arithmetic word with its result, output of `.`, `.s`, `cr`,
// `emit`, `."`, comments, variables and constants, colon definitions compiled once (a later
// redefinition of a word does not change earlier definitions), definitions calling
// definitions, if/else/then, begin/until, begin/while/repeat, do/loop with i and j, +loop;
// errors (unknown word, stack underflow, compile-only word outside a definition, division by
// zero, waits in the foreground, unbalanced control structures, runaway loops) name the word
// and its position, never crash, and leave the interpreter usable; definitions spanning
// lines. Background tasks: two deployed tasks interleave at pause, each with its own stack;
// `ms` waits whole master cycles by the set period; until-no-requests waits across cycles
// until the master's queue is empty; a failing task ends alone with its error kept.
#include "controller/botnana/botnana_interpreter.hpp"

#include <gtest/gtest.h>

#include <map>
#include <string>
#include <tuple>
#include <vector>

namespace omnitwin::botnana {
namespace {

// An object store behind DriveAccess for the language tests: one axis (slave 1, channel 1)
// whose objects are plain values; SDO requests are a counter the test empties. The drive
// words against real drives are in botnana_drive_words_test.cpp.
class StoreAccess : public DriveAccess {
 public:
  bool has_drive(int slave, int ch) const override { return slave == 1 && ch == 1; }
  std::optional<std::int64_t> read(int slave, int ch, std::uint16_t index, std::uint8_t sub) override {
    if (!has_drive(slave, ch)) return std::nullopt;
    const auto it = objects.find({index, sub});
    if (it == objects.end()) return std::nullopt;
    return it->second;
  }
  bool write(int slave, int ch, std::uint16_t index, std::uint8_t sub, std::int64_t v) override {
    if (!has_drive(slave, ch)) return false;
    objects[{index, sub}] = v;
    ++pending;
    return true;
  }
  void set_goal(int, int, PdsGoal g) override { goals.push_back(g); }
  void release_goal(int, int) override {}
  bool requests_pending(int slave) const override { return slave == 1 && pending > 0; }
  std::string last_error() const override { return ""; }

  std::map<std::pair<std::uint16_t, std::uint8_t>, std::int64_t> objects;
  std::vector<PdsGoal> goals;
  int pending = 0;
};

class BotnanaLanguage : public ::testing::Test {
 protected:
  BotnanaLanguage() : in(drives, [this](std::string_view s) { out += s; }) {}
  // Evaluates and expects success.
  void ok(std::string_view line) {
    const Status s = in.evaluate(line);
    ASSERT_TRUE(s.ok) << line << " -> " << s.to_string();
  }
  std::vector<std::int64_t> stack() const { return {in.stack().begin(), in.stack().end()}; }
  std::vector<std::int64_t> eval_stack(std::string_view line) {
    const Status s = in.evaluate(line);
    EXPECT_TRUE(s.ok) << line << " -> " << s.to_string();
    auto r = stack();
    in.evaluate("depth-reset");  // unknown word: empties the stack (errors reset)
    return r;
  }
  StoreAccess drives;
  std::string out;
  Interpreter in;
};

using V = std::vector<std::int64_t>;

TEST_F(BotnanaLanguage, Numbers) {
  EXPECT_EQ(eval_stack("42 -7 $FF 0x10 -$10 0 -0"), (V{42, -7, 255, 16, -16, 0, 0}));
  EXPECT_EQ(eval_stack("9223372036854775807 -9223372036854775808"),
            (V{INT64_MAX, INT64_MIN}));
  const Status s = in.evaluate("1 9223372036854775808");
  EXPECT_FALSE(s.ok);
  EXPECT_EQ(s.word, "9223372036854775808");
  EXPECT_EQ(s.message, "unknown word");
}

TEST_F(BotnanaLanguage, StackWords) {
  EXPECT_EQ(eval_stack("1 dup"), (V{1, 1}));
  EXPECT_EQ(eval_stack("1 2 drop"), (V{1}));
  EXPECT_EQ(eval_stack("1 2 swap"), (V{2, 1}));
  EXPECT_EQ(eval_stack("1 2 over"), (V{1, 2, 1}));
  EXPECT_EQ(eval_stack("1 2 3 rot"), (V{2, 3, 1}));
  EXPECT_EQ(eval_stack("1 2 3 -rot"), (V{3, 1, 2}));
  EXPECT_EQ(eval_stack("1 2 nip"), (V{2}));
  EXPECT_EQ(eval_stack("1 2 tuck"), (V{2, 1, 2}));
  EXPECT_EQ(eval_stack("1 2 2dup"), (V{1, 2, 1, 2}));
  EXPECT_EQ(eval_stack("1 2 3 2drop"), (V{1}));
  EXPECT_EQ(eval_stack("10 20 30 0 pick"), (V{10, 20, 30, 30}));
  EXPECT_EQ(eval_stack("10 20 30 2 pick"), (V{10, 20, 30, 10}));
}

TEST_F(BotnanaLanguage, Arithmetic) {
  EXPECT_EQ(eval_stack("2 3 + 10 4 - 6 7 *"), (V{5, 6, 42}));
  EXPECT_EQ(eval_stack("17 5 / 17 5 mod -17 5 / -17 5 mod"), (V{3, 2, -3, -2}));
  EXPECT_EQ(eval_stack("5 negate -5 abs 3 7 min 3 7 max"), (V{-5, 5, 3, 7}));
  EXPECT_EQ(eval_stack("12 10 and 12 10 or 12 10 xor 0 invert"), (V{8, 14, 6, -1}));
  EXPECT_EQ(eval_stack("1 1+ 1 1-"), (V{2, 0}));
  EXPECT_EQ(eval_stack("-9223372036854775808 -1 /"), (V{INT64_MIN}));  // wraps, no trap
}

TEST_F(BotnanaLanguage, Comparisons) {
  EXPECT_EQ(eval_stack("1 1 = 1 2 = 1 2 <> 1 2 < 2 1 > 2 2 <= 1 2 >="), (V{-1, 0, -1, -1, -1, -1, 0}));
  EXPECT_EQ(eval_stack("0 0= 5 0= -3 0< 3 0< true false 0 not"), (V{-1, 0, -1, 0, -1, 0, -1}));
}

TEST_F(BotnanaLanguage, Output) {
  ok("1 2 .s . . cr 65 emit .\" hi there\" 3 .");
  EXPECT_EQ(out, "<2> 1 2 2 1 \nAhi there3 ");
}

TEST_F(BotnanaLanguage, Comments) {
  EXPECT_EQ(eval_stack("1 ( 2 3 ) 4 \\ 5 6"), (V{1, 4}));
  EXPECT_EQ(eval_stack("1 ( unclosed 2"), (V{1}));
}

TEST_F(BotnanaLanguage, VariablesAndConstants) {
  ok("variable x 100 constant hundred");
  ok("hundred x !  5 x +!  x @");
  EXPECT_EQ(stack(), (V{105}));
  const Status s = in.evaluate("99 @");
  EXPECT_FALSE(s.ok);
  EXPECT_EQ(s.word, "@");
  EXPECT_NE(s.message.find("invalid address"), std::string::npos);
}

TEST_F(BotnanaLanguage, ColonDefinitionsAreCompiledOnce) {
  ok(": sq dup * ;");
  ok(": quad sq sq ;");  // definitions calling definitions
  EXPECT_EQ(eval_stack("3 quad"), (V{81}));
  ok(": sq drop 0 ;");  // a redefinition affects new code only
  EXPECT_EQ(eval_stack("3 quad 3 sq"), (V{81, 0}));
  EXPECT_TRUE(in.defined("QUAD"));  // names are case-insensitive
  EXPECT_EQ(eval_stack("2 QuAd"), (V{16}));
}

TEST_F(BotnanaLanguage, DefinitionsSpanLines) {
  ok(": three");
  EXPECT_TRUE(in.compiling());
  ok("  1 2 ( comment )");
  ok("  + ;");
  EXPECT_FALSE(in.compiling());
  EXPECT_EQ(eval_stack("three"), (V{3}));
}

TEST_F(BotnanaLanguage, IfElseThen) {
  ok(": sign dup 0< if drop -1 else 0= if 0 else 1 then then ;");
  EXPECT_EQ(eval_stack("-5 sign 0 sign 7 sign"), (V{-1, 0, 1}));
  ok(": abs2 dup 0< if negate then ;");
  EXPECT_EQ(eval_stack("-4 abs2 4 abs2"), (V{4, 4}));
}

TEST_F(BotnanaLanguage, BeginUntilAndWhileRepeat) {
  ok(": count-down begin 1- dup 0= until ;");
  EXPECT_EQ(eval_stack("5 count-down"), (V{0}));
  // 0> is not a word of this set: the definition fails and nothing is defined
  EXPECT_FALSE(in.evaluate(": sum-to ( n -- s ) 0 swap begin dup 0> while tuck + swap 1- repeat drop ;").ok);
  EXPECT_FALSE(in.defined("sum-to"));
  ok(": sum-to ( n -- s ) 0 swap begin dup 0 > while tuck + swap 1- repeat drop ;");
  EXPECT_EQ(eval_stack("10 sum-to 0 sum-to"), (V{55, 0}));
}

TEST_F(BotnanaLanguage, DoLoop) {
  ok(": squares 4 0 do i i * loop ;");
  EXPECT_EQ(eval_stack("squares"), (V{0, 1, 4, 9}));
  ok(": pairs 2 0 do 3 1 do j 10 * i + loop loop ;");
  EXPECT_EQ(eval_stack("pairs"), (V{1, 2, 11, 12}));
  ok(": evens 10 0 do i 3 +loop ;");
  EXPECT_EQ(eval_stack("evens"), (V{0, 3, 6, 9}));
  ok(": down 0 10 do i -4 +loop ;");
  EXPECT_EQ(eval_stack("down"), (V{10, 6, 2}));
  ok(": first-over ( lim -- i ) 100 0 do i over > if drop i exit then loop drop -1 ;");
  EXPECT_EQ(eval_stack("5 first-over"), (V{6}));
}

TEST_F(BotnanaLanguage, ErrorsNameWordAndPosition) {
  Status s = in.evaluate("1 2 frobnicate 3");
  EXPECT_FALSE(s.ok);
  EXPECT_EQ(s.word, "frobnicate");
  EXPECT_EQ(s.position, 4u);
  EXPECT_EQ(s.message, "unknown word");
  EXPECT_EQ(s.to_string(), "error: `frobnicate` at position 4: unknown word");
  EXPECT_TRUE(stack().empty());  // the error emptied the stack

  s = in.evaluate("1 +");
  EXPECT_FALSE(s.ok);
  EXPECT_EQ(s.word, "+");
  EXPECT_EQ(s.position, 2u);
  EXPECT_EQ(s.message, "stack underflow");

  s = in.evaluate("1 0 /");
  EXPECT_EQ(s.word, "/");
  EXPECT_EQ(s.message, "division by zero");
  s = in.evaluate("1 0 mod");
  EXPECT_EQ(s.message, "division by zero");

  for (const char* w : {"if", "then", "else", "begin", "until", "while", "repeat", "do", "loop", "i", ";",
                        "exit"}) {
    s = in.evaluate(std::string("1 ") + w);
    EXPECT_FALSE(s.ok) << w;
    EXPECT_EQ(s.word, w);
    EXPECT_EQ(s.position, 2u);
    EXPECT_EQ(s.message, "compile-only word outside a definition") << w;
  }
  // Nothing is left over: the interpreter works as before.
  EXPECT_EQ(eval_stack("2 3 +"), (V{5}));
}

TEST_F(BotnanaLanguage, ErrorInsideDefinitionNamesInnerWord) {
  ok(": bad 1 0 / ;");
  ok(": calls-bad 7 bad ;");
  const Status s = in.evaluate("  calls-bad");
  EXPECT_FALSE(s.ok);
  EXPECT_EQ(s.word, "calls-bad");
  EXPECT_EQ(s.position, 2u);
  EXPECT_NE(s.message.find("division by zero"), std::string::npos) << s.message;
  EXPECT_NE(s.message.find("`/`"), std::string::npos) << s.message;
  EXPECT_NE(s.message.find("`bad`"), std::string::npos) << s.message;
  EXPECT_TRUE(stack().empty());
}

TEST_F(BotnanaLanguage, CompileErrorsDropTheDefinition) {
  Status s = in.evaluate(": broken 1 nosuchword ;");
  EXPECT_FALSE(s.ok);
  EXPECT_EQ(s.word, "nosuchword");
  EXPECT_EQ(s.position, 11u);
  EXPECT_FALSE(in.compiling());
  EXPECT_FALSE(in.defined("broken"));

  s = in.evaluate(": half if 1 ;");
  EXPECT_FALSE(s.ok);
  EXPECT_EQ(s.word, ";");
  EXPECT_NE(s.message.find("unbalanced"), std::string::npos);
  EXPECT_FALSE(in.defined("half"));

  s = in.evaluate(": t then ;");
  EXPECT_EQ(s.word, "then");
  EXPECT_EQ(s.message, "`then` without `if`");
  s = in.evaluate(": t repeat ;");
  EXPECT_EQ(s.word, "repeat");
  s = in.evaluate(": t loop ;");
  EXPECT_EQ(s.word, "loop");
  s = in.evaluate(": outer : inner ; ;");
  EXPECT_EQ(s.word, ":");
  EXPECT_NE(s.message.find("inside a definition"), std::string::npos);
  s = in.evaluate(":");
  EXPECT_EQ(s.message, "missing name after `:`");
  s = in.evaluate(".\" unterminated");
  EXPECT_EQ(s.word, ".\"");
  s = in.evaluate(";deploy");
  EXPECT_EQ(s.word, ";deploy");

  ok(": fine 1 ;");
  EXPECT_EQ(eval_stack("fine fine +"), (V{2}));
}

TEST_F(BotnanaLanguage, WaitsAreRefusedInTheForeground) {
  for (const char* line : {"pause", "10 ms", "until-no-requests", "1 1 until-drive-on", "1 1 until-no-fault",
                           "1 1 until-target-reached"}) {
    const Status s = in.evaluate(line);
    EXPECT_FALSE(s.ok) << line;
    EXPECT_NE(s.message.find("only in a background task"), std::string::npos) << line << ": " << s.message;
  }
  ok(": waits 1 1 until-drive-on ;");  // compiling them is fine
  const Status s = in.evaluate("waits");
  EXPECT_FALSE(s.ok);
  EXPECT_EQ(s.word, "waits");
  EXPECT_NE(s.message.find("until-drive-on"), std::string::npos) << s.message;
  EXPECT_EQ(eval_stack("1 2 +"), (V{3}));
}

TEST_F(BotnanaLanguage, RunawayLoopIsStopped) {
  ok(": forever begin 0 until ;");
  const Status s = in.evaluate("forever");
  EXPECT_FALSE(s.ok);
  EXPECT_NE(s.message.find("runaway"), std::string::npos);
  EXPECT_EQ(eval_stack("1 2 +"), (V{3}));
}

TEST_F(BotnanaLanguage, StackOverflowIsAnError) {
  ok(": fill 2000 0 do i loop ;");
  const Status s = in.evaluate("fill");
  EXPECT_FALSE(s.ok);
  EXPECT_NE(s.message.find("stack overflow"), std::string::npos);
  EXPECT_TRUE(stack().empty());
}

// ---- background tasks ----

TEST_F(BotnanaLanguage, TwoTasksInterleaveAtPause) {
  ok(": a 3 0 do .\" a\" i . pause loop ;");
  ok(": b 2 0 do .\" b\" i . pause loop ;");
  ok("deploy a ;deploy deploy b ;deploy");
  EXPECT_EQ(in.tasks_running(), 2u);
  EXPECT_EQ(out, "");  // nothing runs before the first master cycle
  EXPECT_EQ(in.step_tasks(), 2u);
  EXPECT_EQ(out, "a0 b0 ");
  in.step_tasks();
  EXPECT_EQ(out, "a0 b0 a1 b1 ");
  EXPECT_EQ(in.step_tasks(), 1u);  // b ended after its last pause
  EXPECT_EQ(out, "a0 b0 a1 b1 a2 ");
  EXPECT_EQ(in.step_tasks(), 0u);
  EXPECT_EQ(in.tasks_running(), 0u);
  EXPECT_TRUE(in.last_task_error().ok);
}

TEST_F(BotnanaLanguage, TasksHaveTheirOwnStacks) {
  ok("variable r1 variable r2");
  ok("deploy 1 2 pause + r1 ! ;deploy");
  ok("deploy 10 20 pause * r2 ! ;deploy");
  ok("5");  // the foreground stack is separate too
  in.step_tasks();
  in.step_tasks();
  ok("r1 @ r2 @");
  EXPECT_EQ(stack(), (V{5, 3, 200}));
}

TEST_F(BotnanaLanguage, DeployBodiesSpanLinesAndUseControlFlow) {
  ok("variable n");
  ok("deploy");
  ok("  begin n @ 1+ dup n ! pause 3 = until");
  ok(";deploy");
  for (int k = 0; k < 10; ++k) in.step_tasks();
  ok("n @");
  EXPECT_EQ(stack(), (V{3}));
}

TEST_F(BotnanaLanguage, MsWaitsMasterCycles) {
  in.set_cycle_period_ns(2'000'000);  // 2 ms cycle
  ok("variable done");
  ok("deploy 10 ms -1 done ! ;deploy");  // 10 ms = 5 cycles
  int cycles = 0;
  while (in.tasks_running() > 0 && cycles < 100) {
    in.step_tasks();
    ++cycles;
  }
  EXPECT_EQ(cycles, 6);  // 5 cycles waited, then the store runs on the 6th
  ok("done @");
  EXPECT_EQ(stack(), (V{-1}));
}

TEST_F(BotnanaLanguage, UntilNoRequestsWaitsAcrossCycles) {
  ok("variable after");
  ok("deploy pp 1 1 op-mode! until-no-requests 1 after ! ;deploy");
  in.step_tasks();  // op-mode! queued one request
  EXPECT_EQ((drives.objects[{0x6060, 0}]), 1);
  EXPECT_EQ(drives.pending, 1);
  in.step_tasks();
  in.step_tasks();
  EXPECT_EQ(in.tasks_running(), 1u);
  ok("after @");
  EXPECT_EQ(stack(), (V{0}));
  ok("drop");
  drives.pending = 0;  // the master finished the SDO download
  EXPECT_EQ(in.step_tasks(), 0u);
  ok("after @");
  EXPECT_EQ(stack(), (V{1}));
}

TEST_F(BotnanaLanguage, FailingTaskEndsAloneWithItsError) {
  ok("variable good");
  ok("deploy pause 1 0 / ;deploy");
  ok("deploy pause pause 7 good ! ;deploy");
  in.step_tasks();
  EXPECT_EQ(in.step_tasks(), 1u);
  EXPECT_FALSE(in.last_task_error().ok);
  EXPECT_EQ(in.last_task_error().word, "/");
  EXPECT_NE(in.last_task_error().message.find("division by zero"), std::string::npos);
  EXPECT_NE(out.find("division by zero"), std::string::npos);  // reported on the output too
  EXPECT_EQ(in.step_tasks(), 0u);
  ok("good @");
  EXPECT_EQ(stack(), (V{7}));
}

TEST_F(BotnanaLanguage, RunawayTaskIsEnded) {
  ok("deploy begin 0 until ;deploy");
  EXPECT_EQ(in.step_tasks(), 0u);
  EXPECT_NE(in.last_task_error().message.find("runaway"), std::string::npos);
}

// Found in review: a runaway stopped at a branch was reported as "error: `` at position 49".
// The status names the control word it stopped at, and the line it was compiled from.
TEST_F(BotnanaLanguage, ATaskStoppedAtAControlWordNamesIt) {
  in.set_step_budget(1000);
  ok("deploy 200 begin again ;deploy");
  EXPECT_EQ(in.step_tasks(), 0u);
  EXPECT_EQ(in.last_task_error().word, "again");
  EXPECT_EQ(in.last_task_error().position, 17u);
}

// evaluate() with a line number: a task's error says on which line its word was compiled.
TEST_F(BotnanaLanguage, ATaskErrorSaysTheLineItsWordCameFrom) {
  ASSERT_TRUE(in.evaluate("deploy", 6).ok);
  ASSERT_TRUE(in.evaluate("  1 drop drop ;deploy", 7).ok);
  EXPECT_EQ(in.step_tasks(), 0u);
  EXPECT_EQ(in.last_task_error().word, "drop");
  EXPECT_EQ(in.last_task_error().line, 7u);
  EXPECT_EQ(in.last_task_error().position, 9u);
  EXPECT_EQ(in.last_task_error().located("a.fs").rfind("a.fs:7:10: `drop`: stack underflow", 0), 0u)
      << in.last_task_error().located("a.fs");
}

// A script is checked before it runs (DESIGN: bad input is found and named, file and line):
// unknown words, compile-only words or waits outside a definition or task, unbalanced
// control structures, and a definition or deploy body left open at the end. Words the script
// defines (`:`, `variable`, `constant`) are known after their definition. Nothing runs.
TEST(BotnanaScriptCheck, FindsBadInputWithItsLineWithoutRunningAnything) {
  using L = std::vector<std::string>;
  EXPECT_TRUE(Interpreter::check_script(L{"\\ comment", ": t1 1 1 drive-on ;", "variable v 5 constant k",
                                          "1 1 t1 k v ! .\" hi\"", "deploy t1 1 1 until-drive-on ;deploy"})
                  .ok);
  Status s = Interpreter::check_script(L{"\\ line 1", ": t1 1 1 drive-on ;", "1 1 drvie-on"});
  EXPECT_FALSE(s.ok);
  EXPECT_EQ(s.word, "drvie-on");
  EXPECT_EQ(s.line, 3u);
  EXPECT_EQ(s.position, 4u);
  EXPECT_EQ(s.message, "unknown word");
  EXPECT_EQ(s.located("x.fs"), "x.fs:3:5: `drvie-on`: unknown word");
  s = Interpreter::check_script(L{"", ": move1", "  1 1 drive-on", "  1000 1 1 target-p!"});
  EXPECT_FALSE(s.ok);
  EXPECT_EQ(s.line, 2u);
  EXPECT_EQ(s.position, 0u);
  EXPECT_NE(s.message.find("`move1`"), std::string::npos) << s.message;
  EXPECT_NE(s.message.find("`;`"), std::string::npos) << s.message;
  s = Interpreter::check_script(L{"1 2 +", "  deploy", "  1 1 drive-on"});
  EXPECT_EQ(s.line, 2u);
  EXPECT_EQ(s.position, 2u);
  EXPECT_NE(s.message.find("`;deploy`"), std::string::npos) << s.message;
  s = Interpreter::check_script(L{": a begin 1 ;"});
  EXPECT_EQ(s.word, ";");
  s = Interpreter::check_script(L{"1 1 until-drive-on"});
  EXPECT_EQ(s.word, "until-drive-on");
  s = Interpreter::check_script(L{"1 if"});
  EXPECT_EQ(s.word, "if");
  s = Interpreter::check_script(L{"  .\" open"});
  EXPECT_EQ(s.line, 1u);
  EXPECT_EQ(s.word, ".\"");
  // Numbers at the top level are not pushed: a long script does not overflow the stack.
  EXPECT_TRUE(Interpreter::check_script(L(2000, "1 2 3")).ok);
}

TEST_F(BotnanaLanguage, KillTasks) {
  ok("deploy begin pause 0 until ;deploy deploy begin pause 0 until ;deploy");
  in.step_tasks();
  EXPECT_EQ(in.tasks_running(), 2u);
  in.kill_tasks();
  EXPECT_EQ(in.tasks_running(), 0u);
  EXPECT_EQ(in.step_tasks(), 0u);
}

TEST_F(BotnanaLanguage, DeployErrors) {
  Status s = in.evaluate(": d deploy 1 ;deploy ;");
  EXPECT_EQ(s.word, "deploy");
  s = in.evaluate("deploy 1 ; ;deploy");
  EXPECT_EQ(s.word, ";");
  EXPECT_EQ(in.tasks_running(), 0u);
  EXPECT_FALSE(in.compiling());
}

TEST_F(BotnanaLanguage, RandomInputNeverCrashesAndLeavesItUsable) {
  // Deterministic random lines over the whole vocabulary (control words, defining words,
  // waits, drive words, numbers, junk), evaluated as they come, with tasks stepped between.
  static constexpr const char* kVocab[] = {
      "1", "0", "-1", "3", "$10", "1000", "dup", "drop", "swap", "over", "rot", "-rot", "nip", "tuck",
      "2dup", "2drop", "pick", "+", "-", "*", "/", "mod", "negate", "abs", "min", "max", "and", "or",
      "xor", "invert", "=", "<>", "<", ">", "<=", ">=", "0=", "0<", "true", "false", "1+", "1-", ".",
      ".s", "cr", "emit", ".\" x\"", ".\"", "(", ")", "\\", "variable", "constant", "!", "@", "+!", ":", ";",
      "w1", "w2", "if", "else", "then", "begin", "until", "while", "repeat", "again", "do", "loop", "+loop",
      "i", "j", "exit", "deploy", ";deploy", "pause", "ms", "until-no-requests", "until-drive-on",
      "until-no-fault", "until-target-reached", "drive-on", "go", "op-mode!", "target-p!", "real-p@",
      "drive-wpdo1!", "pds-goal!", "reset-fault", "+drive-homed", "drive-homed?", "zork", "9999999999999999999999"};
  constexpr std::size_t kN = sizeof(kVocab) / sizeof(kVocab[0]);
  in.set_step_budget(20'000);
  std::uint64_t x = 0x9E3779B97F4A7C15ULL;
  const auto next = [&x] {
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    return x;
  };
  int errors = 0;
  for (int line = 0; line < 3000; ++line) {
    std::string text;
    const int words = 1 + static_cast<int>(next() % 12);
    for (int k = 0; k < words; ++k) {
      text += kVocab[next() % kN];
      text += ' ';
    }
    if (!in.evaluate(text).ok) ++errors;
    if (line % 7 == 0) in.step_tasks();
    if (in.tasks_running() > 50) in.kill_tasks();
  }
  EXPECT_GT(errors, 100);  // the input really was mostly wrong
  in.kill_tasks();
  in.evaluate(";deploy");  // close whatever is open (errors reset the compiler)
  in.evaluate(";");
  EXPECT_FALSE(in.compiling());
  EXPECT_EQ(eval_stack("2 3 + : z 4 ; z"), (V{5, 4}));
}

}  // namespace
}  // namespace omnitwin::botnana
