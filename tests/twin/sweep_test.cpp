// Tests twin/sweep: a spec's expansion (the grid's cartesian product with the last key fastest,
// seeded random draws that repeat, both combined), its refusals naming line and key, and
// `omnitwin sweep` through the real program with -j 2: one run directory and point.json per
// point, sweep.csv with every parameter and metric, the plot, `--point K` running one point
// (what a Slurm task does), the notes a `bus` axis over another bus's settings gives, no plot
// when no point ran, a metric no run has and a bad value anywhere in the grid (exit 2); with a stand-in sbatch, a SIGTERM passed on and a refused submission said
// as such. The Slurm path itself: sweep_slow_test.cpp.
#include "twin/sweep.hpp"

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <fstream>
#include <set>
#include <thread>

#include "tests/twin/cli_support.hpp"
#include "twin/scenario.hpp"

namespace omnitwin::twin::cli {
namespace {

using omnitwin::testing::lines_of;

fs::path write_spec(const fs::path& dir, const std::string& name, const std::string& body) {
  fs::create_directories(dir);
  fs::copy_file(test_scenario("run_short_line.yaml"), dir / "line.yaml", fs::copy_options::skip_existing);
  std::ofstream(dir / name) << body;
  return dir / name;
}

// An `sbatch` of the test's own on PATH: a shell script with `body`.
void stand_in_sbatch(const fs::path& bin, const std::string& body) {
  fs::create_directories(bin);
  std::ofstream(bin / "sbatch") << "#!/bin/sh\n" << body;
  fs::permissions(bin / "sbatch", fs::perms::owner_all);
  ::setenv("PATH", (bin.string() + ":" + std::getenv("PATH")).c_str(), 1);
}

class Sweep : public CliTest {};

TEST_F(Sweep, GridIsTheCartesianProductLastKeyFastest) {
  const SweepSpec s = load_sweep(source_path("tests/data/sweeps/short_grid.yaml"));
  EXPECT_EQ(s.name, "short_grid");
  ASSERT_EQ(s.points.size(), 4u);
  EXPECT_EQ(s.params, (std::vector<std::string>{"controller.period", "controller.kp"}));
  EXPECT_EQ(s.points[0][0].second, "0.005");
  EXPECT_EQ(s.points[0][1].second, "[2, 2, 2]");
  EXPECT_EQ(s.points[1][1].second, "[6, 6, 6]");
  EXPECT_EQ(s.points[2][0].second, "0.010");
  EXPECT_EQ(s.plot_x, "controller.period");
  EXPECT_EQ(s.plot_y, "platform.final_error_cm");
}

TEST_F(Sweep, RandomDrawsAreSeededAndCombineWithTheGrid) {
  const std::string body = "scenario: line.yaml\n"
                           "grid: {controller.period: [0.005, 0.010]}\n"
                           "random:\n  draws: 3\n  seed: 7\n  params:\n"
                           "    settle: {min: 0.1, max: 0.5}\n"
                           "    controller.max_speed: {values: [0.3, 0.5]}\n"
                           "metrics: [platform.final_error_cm]\n";
  const SweepSpec a = load_sweep(write_spec(dir_ / "a", "r.yaml", body).string());
  const SweepSpec b = load_sweep(write_spec(dir_ / "b", "r.yaml", body).string());
  ASSERT_EQ(a.points.size(), 6u);  // 2 grid points × 3 draws
  EXPECT_EQ(a.points, b.points);   // the same seed, the same draws
  for (const auto& p : a.points) {
    ASSERT_EQ(p.size(), 3u);
    const double settle = std::stod(p[1].second);
    EXPECT_GE(settle, 0.1);
    EXPECT_LE(settle, 0.5);
    EXPECT_TRUE(p[2].second == "0.3" || p[2].second == "0.5") << p[2].second;
  }
  EXPECT_EQ(a.points[0][1], a.points[3][1]);  // draw 1 with both grid points
  const SweepSpec c = load_sweep(write_spec(dir_ / "c", "r.yaml", std::string(body).replace(body.find("seed: 7"), 7, "seed: 8")).string());
  EXPECT_NE(a.points, c.points);
}

TEST_F(Sweep, BadSpecsNameTheirLineAndKey) {
  struct Bad {
    std::string body, key;
  };
  const Bad bad[] = {
      {"scenario: line.yaml\ngrid: {settle: [1]}\nmetrics: [x]\ncolour: red\n", "colour"},
      {"scenario: nothere.yaml\ngrid: {settle: [1]}\nmetrics: [x]\n", "scenario"},
      {"scenario: line.yaml\nmetrics: [x]\n", "grid"},
      {"scenario: line.yaml\ngrid: {settle: []}\nmetrics: [x]\n", "grid.settle"},
      {"scenario: line.yaml\ngrid: {settle: [1]}\n", "metrics"},
      {"scenario: line.yaml\ngrid: {settle: [1]}\nmetrics: [x]\nplot: {x: kp}\n", "plot.x"},
      {"scenario: line.yaml\nrandom: {draws: 0, params: {settle: {min: 0, max: 1}}}\nmetrics: [x]\n", "random.draws"},
      {"scenario: line.yaml\nrandom: {draws: 2, params: {settle: {min: 2, max: 1}}}\nmetrics: [x]\n", "random.params.settle"},
      {"scenario: line.yaml\ngrid: {no_such_key: [1]}\nmetrics: [x]\n", "no_such_key"},
      // A grid past 100000 points is refused at the key that passes it, before it is built.
      {"scenario: line.yaml\ngrid: {a: [0,1,2,3,4,5,6,7,8,9], b: [0,1,2,3,4,5,6,7,8,9], c: [0,1,2,3,4,5,6,7,8,9], "
       "d: [0,1,2,3,4,5,6,7,8,9], e: [0,1,2,3,4,5,6,7,8,9], f: [0,1]}\nmetrics: [x]\n", "grid.f"},
  };
  for (const Bad& b : bad) {
    SCOPED_TRACE(b.body);
    try {
      load_sweep(write_spec(dir_ / "bad", "s.yaml", b.body).string());
      ADD_FAILURE() << "accepted";
    } catch (const ScenarioError& e) {
      EXPECT_TRUE(contains(e.key(), b.key)) << e.what();
    } catch (const std::exception& e) {
      ADD_FAILURE() << "not a ScenarioError: " << e.what();
    }
  }
}

// The whole sweep through the program, two points at a time.
TEST_F(Sweep, RunsEveryPointAndWritesTheTableAndThePlot) {
  const fs::path out = dir_ / "out";
  const Finished f = run({"sweep", source_path("tests/data/sweeps/short_grid.yaml"), "-j", "2", "--out", out.string()});
  ASSERT_EQ(f.code, 0) << f.out << f.err;
  EXPECT_TRUE(contains(f.out, "4 points, 4 ran, 0 failed to run")) << f.out;
  const auto rows = lines_of(read_bytes(out / "sweep.csv"));
  ASSERT_EQ(rows.size(), 5u);
  EXPECT_EQ(rows[0], "point,controller.period,controller.kp,platform.final_error_cm,platform.iae_contour_cm,passed,exit_code");
  EXPECT_TRUE(rows[2].starts_with("2,\"0.005\",\"[6, 6, 6]\",")) << rows[2];
  for (int k = 1; k <= 4; ++k) {
    const fs::path d = out / "points" / fmt::format("{:04d}", k);
    const nlohmann::json pj = nlohmann::json::parse(read_bytes(d / "point.json"));
    EXPECT_EQ(pj.at("point"), k);
    EXPECT_EQ(pj.at("exit_code"), 0);
    EXPECT_TRUE(fs::is_regular_file(d / "trajectory.csv"));
  }
  // kp 6 follows the line more closely than kp 2 (the columns carry each run's own results).
  const auto final_error = [&](int k) {
    const nlohmann::json m = nlohmann::json::parse(read_bytes(out / "points" / fmt::format("{:04d}", k) / "metrics.json"));
    return m.at("platform").at("final_error_cm").get<double>();
  };
  EXPECT_LT(final_error(2), final_error(1));
  EXPECT_TRUE(contains(rows[2], fmt::format("{}", final_error(2)))) << rows[2];
  EXPECT_GT(fs::file_size(out / "sweep.png"), 1000u);
}

// Realtime points share the scenario's bus, so -j 2 runs them one after the other: at once,
// each master heard the other's frames and NMT stop, and both points ended far from the goal
// (14.8 cm against 0.2-0.5 cm; found in review).
TEST_F(Sweep, RealtimePointsRunOneAtATimeWhateverTheJobs) {
  const fs::path out = dir_ / "rt";
  const Finished f = run({"sweep", source_path("tests/data/sweeps/realtime_pair.yaml"), "-j", "2", "--out", out.string()});
  ASSERT_EQ(f.code, 0) << f.out << f.err;
  for (int k = 1; k <= 2; ++k) {
    const nlohmann::json m = nlohmann::json::parse(read_bytes(out / "points" / fmt::format("{:04d}", k) / "metrics.json"));
    // On a miss, what the point saw: another sender (foreign_frames, master_changes), lateness
    // (realtime overruns), its master's end.
    EXPECT_LT(m.at("platform").at("final_error_cm").get<double>(), 2.0)
        << "point " << k << "\nbus: " << m.at("bus").dump() << "\nrealtime: " << m.at("realtime").dump()
        << "\nmaster: " << m.at("master").dump() << "\n" << f.out;
    EXPECT_EQ(m.at("bus").at("frames_rx").get<double>() > 0, true);
  }
}

// SIGTERM to `sweep --slurm` while `sbatch --wait` waits: passed on to sbatch (which cancels its
// array), and the sweep ends at once with exit 3. It used to wait for every task (found in
// review). A stand-in sbatch on PATH that only waits, and says when it is told to stop.
TEST_F(Sweep, SigtermDuringSlurmPassesOnToSbatchAndEnds) {
  stand_in_sbatch(dir_ / "bin", "sleep 60 &\ntrap 'kill $!; echo cancelled > " + (dir_ / "sbatch-term").string() +
                                    "; exit 143' TERM\nwait $!\n");
  const fs::path out = dir_ / "slurm";
  Child c({"sweep", source_path("tests/data/sweeps/short_grid.yaml"), "--slurm", "--out", out.string()}, work(), io());
  ASSERT_TRUE(c.wait_for_output("submitting")) << c.out() << c.err();
  std::this_thread::sleep_for(300ms);
  c.signal(SIGTERM);
  EXPECT_EQ(c.wait(10s), 3) << c.out() << c.err();
  EXPECT_TRUE(fs::exists(dir_ / "sbatch-term")) << "sbatch was not told to stop";
}

// An sbatch that could not submit (Slurm unreachable): the sweep says that the array did not
// run and ends with exit 3, writing no table or plot. It said "some tasks failed", then wrote a
// table of four failed points and an empty plot (found by a walkthrough of the docs).
TEST_F(Sweep, ASubmissionSbatchRefusedIsSaidAsSuch) {
  stand_in_sbatch(dir_ / "bin", "echo 'sbatch: error: Batch job submission failed: Unable to contact slurm controller' >&2\n"
                                "exit 1\n");
  const fs::path out = dir_ / "refused";
  const Finished f = run({"sweep", source_path("tests/data/sweeps/short_grid.yaml"), "--slurm", "--out", out.string()});
  EXPECT_EQ(f.code, 3) << f.out << f.err;
  EXPECT_TRUE(contains(f.err, "sbatch --wait ended with 1 and none of the 4 tasks wrote a result: the job array did "
                              "not run"))
      << f.err;
  EXPECT_FALSE(contains(f.out, "some tasks failed")) << f.out;
  EXPECT_FALSE(fs::exists(out / "sweep.csv"));
  EXPECT_FALSE(fs::exists(out / "sweep.png"));
}

// A local sweep whose every point failed to run (masters that end at once): the table says so,
// and there is no plot of no point (an empty frame was written as sweep.png).
TEST_F(Sweep, NoPointRanNoPlot) {
  const fs::path spec = write_spec(dir_ / "nopoint", "s.yaml",
                                   "scenario: line.yaml\ngrid: {bus: [can], bus.master: [/bin/false, /bin/true]}\n"
                                   "metrics: [platform.final_error_cm]\n");
  const fs::path out = dir_ / "nopoint-out";
  const Finished f = run({"sweep", spec.string(), "--out", out.string()});
  EXPECT_EQ(f.code, 3) << f.out << f.err;
  EXPECT_TRUE(contains(f.out, "2 points, 0 ran, 2 failed to run")) << f.out;
  EXPECT_TRUE(contains(f.err, "no plot: no point ran")) << f.err;
  EXPECT_TRUE(fs::exists(out / "sweep.csv"));
  EXPECT_FALSE(fs::exists(out / "sweep.png"));
}

// A metric that no run's metrics.json holds (a typo) is bad input, exit 2 naming it, once the
// runs are there; it passed with an empty column and an empty plot (found in review).
TEST_F(Sweep, AMetricNoRunHasIsBadInput) {
  const fs::path spec = write_spec(dir_ / "typo", "s.yaml",
                                   "scenario: line.yaml\ngrid: {controller.period: [0.01]}\n"
                                   "metrics: [platform.final_error_cm, platform.final_eror_cm]\n");
  const Finished f = run({"sweep", spec.string(), "--out", (dir_ / "typo-out").string()});
  EXPECT_EQ(f.code, 2) << f.out << f.err;
  EXPECT_TRUE(contains(f.err, "metrics: 'platform.final_eror_cm' is in none of the runs' metrics.json")) << f.err;
  EXPECT_FALSE(contains(f.err, "'platform.final_error_cm'")) << f.err;
}

// Every value of the grid is loaded before any run: a bad second value is exit 2 naming the
// point and the key, and nothing runs (only the first point was checked: point 1 ran, then
// point 2 failed with its reason in point.json only; found in review).
TEST_F(Sweep, ABadValueAnywhereInTheGridStopsTheSweepBeforeItRuns) {
  const fs::path spec = write_spec(dir_ / "badval", "s.yaml",
                                   "scenario: line.yaml\ngrid: {settle: [0.5, -1]}\nmetrics: [platform.final_error_cm]\n");
  const fs::path out = dir_ / "badval-out";
  const Finished f = run({"sweep", spec.string(), "--out", out.string()});
  EXPECT_EQ(f.code, 2) << f.out << f.err;
  EXPECT_TRUE(contains(f.err, "settle: point 2 does not load: --set: settle: -1 is out of range")) << f.err;
  EXPECT_FALSE(fs::exists(out / "points")) << "a point ran";
}

// Found by the bad-input round: a point folder holding a user's file ran the points before it
// and then failed that point's run with exit 3. It is refused before anything runs.
TEST_F(Sweep, APointFolderHoldingSomethingElseIsRefusedBeforeAnythingRuns) {
  const fs::path spec = write_spec(dir_ / "busy", "s.yaml",
                                   "scenario: line.yaml\ngrid: {settle: [0.5, 0.6]}\nmetrics: [platform.final_error_cm]\n");
  const fs::path out = dir_ / "busy-out";
  fs::create_directories(out / "points" / "0002");
  std::ofstream(out / "points" / "0002" / "notes.txt") << "mine\n";
  const Finished f = run({"sweep", spec.string(), "--out", out.string()});
  EXPECT_EQ(f.code, 2) << f.out << f.err;
  EXPECT_TRUE(contains(f.err, "0002 holds something that is not an earlier sweep's point")) << f.err;
  EXPECT_FALSE(fs::exists(out / "points" / "0001")) << "a point ran";
  EXPECT_TRUE(fs::exists(out / "points" / "0002" / "notes.txt")) << "the user's file is gone";
}

// A random real keeps every digit it was drawn with and stays in [min, max]; whole-number
// bounds draw whole numbers. The draws were printed with 6 digits: two of three equal and
// one below min in this range (found in review).
TEST_F(Sweep, RandomDrawsKeepTheirDigitsAndTheirRange) {
  const std::string body = "scenario: line.yaml\ngrid: {bus: [can]}\n"
                           "random:\n  draws: 20\n  seed: 3\n  params:\n"
                           "    platform.motor.friction_torque: {min: 0.1000001, max: 0.1000009}\n"
                           "    bus.bit_rate: {min: 125000, max: 1000000}\n"
                           "metrics: [platform.final_error_cm]\n";
  const SweepSpec a = load_sweep(write_spec(dir_ / "a", "r.yaml", body).string());
  ASSERT_EQ(a.points.size(), 20u);
  std::set<std::string> seen;
  for (const auto& p : a.points) {
    ASSERT_EQ(p.size(), 3u);
    const double v = std::stod(p[1].second);
    EXPECT_GE(v, 0.1000001) << p[1].second;
    EXPECT_LE(v, 0.1000009) << p[1].second;
    seen.insert(p[1].second);
    EXPECT_EQ(p[2].second.find_first_not_of("0123456789"), std::string::npos) << p[2].second;
    const long rate = std::stol(p[2].second);
    EXPECT_GE(rate, 125000);
    EXPECT_LE(rate, 1000000);
  }
  EXPECT_EQ(seen.size(), 20u) << "draws collapsed onto each other";
}

// A second sweep into the same folder never reports the first one's results: point 2 cannot
// run this time (its master ends at once), and its row read the earlier run's metrics (found in
// review). A string metric holding a comma (the scenario's path here) is quoted in the table.
TEST_F(Sweep, AnEarlierSweepsResultsAreNotReadAsThisOnesAndStringsAreQuoted) {
  const fs::path spec_dir = dir_ / "d,1";
  const std::string master = omnitwin::testing::binary_path("controller/omni-master");
  const auto spec = [&](const std::string& second) {
    return write_spec(spec_dir, "s.yaml",
                      "name: s\nscenario: line.yaml\ngrid: {bus: [can], bus.master: [" + master + ", " + second +
                          "]}\nmetrics: [platform.final_error_cm, scenario_file]\n");
  };
  const fs::path out = dir_ / "out";
  const Finished first = run({"sweep", spec(master).string(), "--out", out.string()});
  ASSERT_EQ(first.code, 0) << first.out << first.err;
  const Finished second = run({"sweep", spec("/bin/false").string(), "--out", out.string()});
  EXPECT_EQ(second.code, 3) << second.out << second.err;
  EXPECT_TRUE(contains(second.out, "2 points, 1 ran, 1 failed to run")) << second.out;
  const auto rows = lines_of(read_bytes(out / "sweep.csv"));
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_TRUE(rows[2].starts_with("2,\"can\",\"/bin/false\",,,false,3")) << rows[2];
  // What point 2's folder holds is this sweep's failed run, not the earlier one's.
  const nlohmann::json m = nlohmann::json::parse(read_bytes(out / "points/0002/metrics.json"));
  EXPECT_TRUE(contains(m.value("error", ""), "the master did not connect to the sim clock (it ended first: exit 1"))
      << m.dump(2);
  // Every row has the header's number of fields for a CSV reader.
  const std::string parse = "python3 -c \"import csv, sys; r = list(csv.reader(open(sys.argv[1]))); "
                            "sys.exit(0 if all(len(x) == len(r[0]) for x in r) else 1)\" '" +
                            (out / "sweep.csv").string() + "'";
  EXPECT_EQ(std::system(parse.c_str()), 0) << read_bytes(out / "sweep.csv");
}

// The Slurm script takes the sweep's name, the spec's folder and --out as data, whatever they
// hold: a name with a line break and a command, a folder and an output path with a quote and
// a space. The name's command ran when the script did, and the quoted paths broke the exec
// line (found in review). A stand-in sbatch runs the script as task 1.
TEST_F(Sweep, TheSlurmScriptQuotesWhatItIsGiven) {
  stand_in_sbatch(dir_ / "bin", "for a; do last=$a; done\nprintf '%s\\n' \"$@\" > '" + (dir_ / "args").string() +
                                    "'\nSLURM_ARRAY_TASK_ID=1 sh \"$last\"\n");
  const fs::path pwned = dir_ / "PWNED";
  const fs::path spec = write_spec(dir_ / "q'd ir", "s.yaml",
                                   "name: \"x\\ntouch " + pwned.string() + "\"\nscenario: line.yaml\n"
                                   "grid: {controller.period: [0.005, 0.010]}\nmetrics: [platform.final_error_cm]\n");
  const fs::path out = dir_ / "out q'B";
  const Finished f = run({"sweep", spec.string(), "--slurm", "--out", out.string()});
  EXPECT_EQ(f.code, 3) << f.out << f.err;  // point 2 never ran: the stand-in ran task 1 only
  EXPECT_FALSE(fs::exists(pwned)) << read_bytes(out / "sweep.sbatch");
  const nlohmann::json pj = nlohmann::json::parse(read_bytes(out / "points/0001/point.json"));
  EXPECT_EQ(pj.at("exit_code"), 0);
  EXPECT_TRUE(contains(read_bytes(out / "sweep.sbatch"), "#SBATCH --job-name=omnitwin-sweep-x_touch_"))
      << read_bytes(out / "sweep.sbatch");
  EXPECT_TRUE(contains(read_bytes(dir_ / "args"), "--output=" + (out / "slurm-%A_%a.out").string()))
      << read_bytes(dir_ / "args");
}

// A `bus` axis over a file with another bus's settings: each point's run leaves those settings
// out (scenario.cpp's switch_bus_type); the sweep says so once, not once per point, and each
// point.json keeps its notes. It used to say nothing (the notes were only in each run.json).
TEST_F(Sweep, ABusAxisOverAnotherBussSettingsSaysWhatItLeftOutOnce) {
  fs::create_directories(dir_ / "s");
  std::ofstream(dir_ / "s" / "can_line.yaml") << "platform: {variant: capsule}\n"
                                                 "bus: {type: can, bit_rate: 250000, isr_us: 3300, seed: 4}\n"
                                                 "path: {segments: [{line: {dx: 0.2, duration: 1}}]}\n"
                                                 "outputs: {video: false, report: false}\n";
  std::ofstream(dir_ / "s" / "bus.yaml") << "scenario: can_line.yaml\n"
                                            "grid: {bus: [direct], settle: [0.1, 0.2]}\n"
                                            "metrics: [platform.final_error_cm]\n";
  const fs::path out = dir_ / "bus_out";
  const Finished f = run({"sweep", (dir_ / "s" / "bus.yaml").string(), "-j", "2", "--out", out.string()});
  ASSERT_EQ(f.code, 0) << f.out << f.err;
  const std::string note = "bus direct instead of the file's can: the file's can settings bit_rate, isr_us, seed are left out";
  const std::string said = "omnitwin sweep: note (point ";
  ASSERT_TRUE(contains(f.err, said)) << f.err;
  EXPECT_EQ(f.err.find(said), f.err.rfind(said)) << f.err;  // once for both points
  EXPECT_TRUE(contains(f.err, note)) << f.err;
  for (int k = 1; k <= 2; ++k) {
    const nlohmann::json pj = nlohmann::json::parse(read_bytes(out / "points" / fmt::format("{:04d}", k) / "point.json"));
    EXPECT_EQ(pj.at("notes"), nlohmann::json::array({note})) << pj.dump();
    EXPECT_EQ(pj.at("exit_code"), 0);
  }
  // One point alone (a Slurm task) prints its own.
  const Finished g = run({"sweep", (dir_ / "s" / "bus.yaml").string(), "--point", "2", "--out", (dir_ / "one").string()});
  ASSERT_EQ(g.code, 0) << g.out << g.err;
  EXPECT_TRUE(contains(g.err, "omnitwin sweep: note: " + note)) << g.err;
  // Through Slurm (a stand-in sbatch that runs both tasks), the sweep gathers the tasks' notes
  // from their point.json and says each once, with how many points gave it.
  stand_in_sbatch(dir_ / "bin", "for a; do last=$a; done\nfor t in 1 2; do SLURM_ARRAY_TASK_ID=$t sh \"$last\"; done\n");
  const Finished h = run({"sweep", (dir_ / "s" / "bus.yaml").string(), "--slurm", "--out", (dir_ / "slurm").string()});
  ASSERT_EQ(h.code, 0) << h.out << h.err;
  EXPECT_TRUE(contains(h.err, "omnitwin sweep: note (2 of 2 points, the first point 1): " + note)) << h.err;
}

TEST_F(Sweep, PointRunsOnlyThatPoint) {
  const fs::path out = dir_ / "one";
  const Finished f = run({"sweep", source_path("tests/data/sweeps/short_grid.yaml"), "--point", "3", "--out", out.string()});
  ASSERT_EQ(f.code, 0) << f.out << f.err;
  EXPECT_TRUE(fs::is_regular_file(out / "points/0003/point.json"));
  EXPECT_FALSE(fs::exists(out / "points/0001"));
  EXPECT_FALSE(fs::exists(out / "sweep.csv"));
  const Finished g = run({"sweep", source_path("tests/data/sweeps/short_grid.yaml"), "--point", "5", "--out", out.string()});
  EXPECT_EQ(g.code, 2);
  EXPECT_TRUE(contains(g.err, "the sweep has 4 points")) << g.err;
}

}  // namespace
}  // namespace omnitwin::twin::cli
