// twin layer — the experiment registry and the output helpers every experiment shares
// (folder, text files, the matplotlib subprocess); see experiment.hpp.
//
// Plots are drawn by a Python script (media/plots/plot_experiment.py) run as a subprocess, so
// the C++ side needs no plotting library and a missing matplotlib only costs the PNGs: the
// CSV and markdown are always written first.
#include "twin/experiment.hpp"

#include "twin/records.hpp"
#include "twin/run_directory.hpp"

#include <sys/wait.h>
#include <array>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <stdexcept>

#include <fmt/format.h>

namespace omnitwin::twin {

namespace fs = std::filesystem;

namespace {

struct Registered {
  const char* name;
  int (*run)(const ExperimentOptions&);
  bool takes_sets = false;    // runs scenarios of the user's and applies --set to each
  bool takes_model = false;   // --model
  bool takes_budget = false;  // --budget
};

// The registry: one row per `omnitwin experiment NAME`.
std::array<Registered, 6> registry() {
  return {{{"can-timing", run_can_timing},
           {"can-dropout", run_can_dropout},
           {"thesis-platform", run_thesis_platform, true, true},
           {"m3-cycle", run_m3_cycle},
           {"thesis-calibrate", run_thesis_calibrate, true, true, true},
           {"fast-model", run_fast_model}}};
}

// `text` as one single-quoted shell word.
std::string shell_quote(const std::string& text) {
  std::string out = "'";
  for (const char c : text) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

// Exit status of a std::system() call (-1 when the shell could not run or was signalled).
int exit_status(int raw) {
  if (raw == -1 || !WIFEXITED(raw)) return -1;
  return WEXITSTATUS(raw);
}

// True when `interpreter` runs and can import matplotlib.
bool has_matplotlib(const std::string& interpreter) {
  const std::string cmd = interpreter + " -c 'import matplotlib' >/dev/null 2>&1";
  return exit_status(std::system(cmd.c_str())) == 0;
}

// True when `interpreter` runs at all.
bool runs(const std::string& interpreter) {
  const std::string cmd = interpreter + " -c 'pass' >/dev/null 2>&1";
  return exit_status(std::system(cmd.c_str())) == 0;
}

// The Debian interpreter first (the PATH one may be a private install without matplotlib),
// then python3 from PATH. Empty when neither can import matplotlib; `any_python` says
// whether some python3 ran at all.
std::string find_plot_interpreter(bool& any_python) {
  any_python = false;
  for (const std::string candidate : {"/usr/bin/python3", "python3"}) {
    if (!runs(candidate)) continue;
    any_python = true;
    if (has_matplotlib(candidate)) return candidate;
  }
  return {};
}

// An experiment's folder must not be a run's (its files would mix with the run's records;
// `model --out` refuses the same), and what an earlier experiment left under runs/ goes:
// rows of this experiment must not sit beside 64 stale run folders of a longer earlier one
// (both found by a walkthrough). Only folders holding a run's marker are removed.
void clear_earlier_runs(const fs::path& out) {
  std::error_code ec;
  if (fs::exists(out / kRunMarker, ec))
    throw experiment::BadInput(fmt::format("--out {} is a run directory; choose another folder", out.string()));
  const fs::path runs = out / "runs";
  if (!fs::is_directory(runs, ec)) return;
  std::vector<fs::path> stale;
  for (auto it = fs::recursive_directory_iterator(runs, fs::directory_options::skip_permission_denied, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (!it->is_directory(ec) || !fs::exists(it->path() / kRunMarker, ec)) continue;
    stale.push_back(it->path());
    it.disable_recursion_pending();  // a run's own folders are the run's
  }
  for (const fs::path& d : stale) fs::remove_all(d, ec);
}

}  // namespace

std::vector<std::string> experiment_names() {
  std::vector<std::string> names;
  for (const Registered& r : registry()) names.emplace_back(r.name);
  return names;
}

int run_experiment(const std::string& name, const ExperimentOptions& options) {
  for (const Registered& r : registry()) {
    if (name != r.name) continue;
    // Any exception is a runtime failure (exit 3), never a crash of the CLI.
    try {
      // An option the experiment has no use for is bad input, not silently dropped (--model
      // and --budget were; found by a walkthrough).
      if (!options.sets.empty() && !r.takes_sets)
        throw experiment::BadInput("--set is for thesis-platform and thesis-calibrate only");
      if (!options.model.empty() && !r.takes_model)
        throw experiment::BadInput("--model is for thesis-platform and thesis-calibrate only");
      if (options.budget != 0 && !r.takes_budget) throw experiment::BadInput("--budget is for thesis-calibrate only");
      clear_earlier_runs(options.out_dir.empty() ? fs::path("out") / name : fs::path(options.out_dir));
      return r.run(options);
    } catch (const ScenarioError& e) {
      // A bad scenario (--model, a key) is bad input, as for run (found in review: it was 3).
      std::cerr << "omnitwin experiment " << name << ": " << e.what() << "\n";
      return kExperimentUnknown;
    } catch (const experiment::BadInput& e) {
      std::cerr << "omnitwin experiment " << name << ": " << e.what() << "\n";
      return kExperimentUnknown;
    } catch (const experiment::Interrupted& e) {
      std::cerr << "omnitwin experiment " << name << ": " << e.what() << "\n";
      return kExperimentRuntimeError;
    } catch (const std::exception& e) {
      std::cerr << "omnitwin experiment " << name << ": " << e.what() << "\n";
      return kExperimentRuntimeError;
    }
  }
  std::cerr << "omnitwin experiment: unknown experiment '" << name << "'; known:";
  for (const std::string& n : experiment_names()) std::cerr << " " << n;
  std::cerr << "\n";
  return kExperimentUnknown;
}

namespace experiment {

void stop_if_interrupted(const std::atomic<bool>* interrupt) {
  if (interrupt && interrupt->load()) throw Interrupted("interrupted (Ctrl-C or SIGTERM); no summary files written");
}

void stop_if_interrupted(const ExperimentOptions& options) { stop_if_interrupted(options.interrupt); }

std::filesystem::path output_dir(const std::string& name, const ExperimentOptions& options) {
  stop_if_interrupted(options);
  const std::filesystem::path dir =
      options.out_dir.empty() ? std::filesystem::path("out") / name : std::filesystem::path(options.out_dir);
  std::error_code ec;
  if (std::filesystem::exists(dir, ec) && !std::filesystem::is_directory(dir, ec))
    throw BadInput("--out " + dir.string() + " is an existing file, not a folder");
  std::filesystem::create_directories(dir);
  return dir;
}

void write_text(const std::filesystem::path& path, const std::string& text) {
  // Found in review: written in place, an interrupt or a full disk left half a file.
  write_text_atomic(path.string(), text);
}

bool plot(const std::string& kind, const std::filesystem::path& csv, const std::filesystem::path& out_dir) {
  // Find a python3 that has matplotlib; name the missing Debian package otherwise.
  bool any_python = false;
  const std::string python = find_plot_interpreter(any_python);
  if (python.empty()) {
    std::cerr << "warning: no plots for " << kind << ": "
              << (any_python ? "python3-matplotlib is not installed (apt-get install python3-matplotlib)"
                             : "python3 is not installed (apt-get install python3 python3-matplotlib)")
              << "; the CSV and markdown are complete\n";
    return false;
  }
  // Run the script from the source tree with the CSV and the output folder.
  const std::string script = std::string(OMNITWIN_SOURCE_DIR) + "/media/plots/plot_experiment.py";
  const std::string cmd = python + " " + shell_quote(script) + " " + shell_quote(kind) + " " +
                          shell_quote(csv.string()) + " " + shell_quote(out_dir.string());
  const int status = exit_status(std::system(cmd.c_str()));
  if (status != 0) {
    std::cerr << "warning: the plot script failed for " << kind << " (exit " << status << "): " << script << "\n";
    return false;
  }
  return true;
}

}  // namespace experiment

}  // namespace omnitwin::twin
