// libFuzzer target for controller/botnana: the Botnana Control word set, the one text language
// the project reads from its users (omni-master's `--script FILE` and its shell's typed lines).
//
// The input is source text, cut into lines at '\n' (at most 64). Each line is evaluated, as
// the shell does, then one master cycle runs (the background tasks' step, then the drives'
// period) over three CiA 402 drive cores behind the test suite's DriveHarness (slave 1
// channels 1 and 2, slave 2 channel 1). After the last line 32 more cycles let deployed
// tasks run on. A small step budget keeps runaway loops cheap (the interpreter must stop them
// itself: a hang is a finding).
//
// What the interpreter promises (botnana_interpreter.hpp) and the target checks, aborting on
// a mismatch: evaluate() never throws; an error names a word position inside the line, says
// what went wrong, and leaves an empty data stack and no definition being compiled; the data
// stack never exceeds kMaxDataStack; a failed task's error is reported the same way.
//
//   (built by fuzz/CMakeLists.txt with the EtherCAT fuzz library, which holds the drive core)
//   build/fuzz/botnana_fuzz -dict=fuzz/botnana.dict fuzz/corpus/botnana -max_total_time=30
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "controller/botnana/botnana_interpreter.hpp"
#include "tests/controller/botnana/drive_harness.hpp"

using namespace omnitwin::botnana;

namespace {

constexpr std::size_t kMaxLines = 64;
constexpr int kTailCycles = 32;
constexpr std::uint64_t kBudget = 20'000;  // instructions per evaluate() or task step

void check_status(const Status& s, std::size_t line_size) {
  if (s.ok) return;
  if (s.message.empty() || s.to_string().rfind("error: ", 0) != 0) std::abort();
  if (s.position > line_size) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  testing::DriveHarness h;
  h.add_axis(1, 1);
  h.add_axis(1, 2);
  h.add_axis(2, 1);
  std::size_t printed = 0;
  Interpreter in(h, [&printed](std::string_view s) { printed += s.size(); });
  in.set_step_budget(kBudget);
  std::size_t start = 0, lines = 0;
  while (start <= text.size() && lines < kMaxLines) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view line = text.substr(start, end - start);
    const Status s = in.evaluate(line);
    check_status(s, line.size());
    // An error empties the data stack and drops a definition being compiled.
    if (!s.ok && (!in.stack().empty() || in.compiling())) std::abort();
    if (in.stack().size() > Interpreter::kMaxDataStack) std::abort();
    in.step_tasks();
    check_status(in.last_task_error(), std::string_view::npos);
    h.cycle();
    start = end + 1;
    ++lines;
  }
  for (int k = 0; k < kTailCycles && in.tasks_running() > 0; ++k) {
    in.step_tasks();
    check_status(in.last_task_error(), std::string_view::npos);
    h.cycle();
  }
  (void)printed;
  return 0;
}
