// Tests media/run_report: the run report and the check index that the Python scripts in
// media/report draw. A copy of a real short CAN run (tests/data/runs/can_fault/, made by
// make_fixture.sh: node 2 loses power, two expectations hold and one fails) gets a
// report.html whose PASS/FAIL rows match metrics.json, whose plots exist as valid PNGs, and
// whose links all resolve to files of the run; an interrupted run, a run without
// metrics.json and an older run without run.json/bus.csv still get a page that says so;
// missing run directories, interpreters and scripts, failing or hung scripts are ok = false
// with a message, never an exception. The check index counts "1 passed, 1 failed" and
// links each report relative to itself.
#include "media/run_report.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <algorithm>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tests/support/temp_dir.hpp"

namespace omnitwin::media {
namespace {

namespace fs = std::filesystem;
using omnitwin::testing::read_bytes;
using omnitwin::testing::TempDir;

const fs::path kFixture = fs::path(OMNITWIN_SOURCE_DIR) / "tests" / "data" / "runs" / "can_fault";

ReportTools tools() {
  ReportTools t;
  t.scripts_dir = std::string(OMNITWIN_SOURCE_DIR) + "/media/report";
  return t;
}

// A private copy of the fixture run directory (the report writes into it).
fs::path copy_fixture(const TempDir& tmp) {
  const fs::path run = tmp / "run";
  fs::copy(kFixture, run, fs::copy_options::recursive);
  return run;
}

void write_file(const fs::path& p, const std::string& text) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f << text;
}

nlohmann::json read_json(const fs::path& p) { return nlohmann::json::parse(read_bytes(p)); }

// The values of every `attr="..."` in a page, in order (attr includes its left context,
// e.g. "<img src").
std::vector<std::string> attributes(const std::string& page, const std::string& attr) {
  std::vector<std::string> out;
  const std::string open = attr + "=\"";
  for (size_t at = page.find(open); at != std::string::npos; at = page.find(open, at + 1)) {
    const size_t begin = at + open.size(), end = page.find('"', begin);
    if (end == std::string::npos) break;
    out.push_back(page.substr(begin, end - begin));
  }
  return out;
}

// Every href and src value of a page.
std::vector<std::string> links_of(const std::string& page) {
  std::vector<std::string> out = attributes(page, " href");
  for (const auto& s : attributes(page, " src")) out.push_back(s);
  return out;
}

std::vector<std::string> images_of(const std::string& page) { return attributes(page, "<img src"); }

// The result cell ("PASS", "FAIL", "NOT EVALUATED") of the expectation row for `metric`.
std::string result_of(const std::string& page, const std::string& metric) {
  const size_t row = page.find("<tr><td>" + metric + "</td>");
  if (row == std::string::npos) return "";
  const size_t row_end = page.find("</tr>", row);
  const std::string cls = "<td class=\"";
  for (const char* c : {"PASS", "FAIL", "NOTEVALUATED"}) {
    const size_t at = page.find(cls + c + "\">", row);
    if (at < row_end) {
      const size_t begin = page.find('>', at) + 1;
      return page.substr(begin, page.find('<', begin) - begin);
    }
  }
  return "";
}

std::string html_escaped(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '&') out += "&amp;";
    else if (c == '<') out += "&lt;";
    else if (c == '>') out += "&gt;";
    else if (c == '"') out += "&quot;";
    else if (c == '\'') out += "&#x27;";
    else out += c;
  }
  return out;
}

bool is_png(const fs::path& p) {
  const std::string bytes = read_bytes(p);
  return bytes.size() > 8 && bytes.compare(0, 8, "\x89PNG\r\n\x1a\n") == 0;
}

size_t count_of(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

// The report of `run`, asserted to succeed; returns the page.
std::string report_of(const fs::path& run) {
  const ReportResult r = write_run_report(run.string(), tools());
  EXPECT_TRUE(r.ok) << r.error;
  EXPECT_EQ(r.path, (run / "report.html").string());
  EXPECT_GT(r.seconds, 0.0);
  return read_bytes(run / "report.html");
}

TEST(RunReport, ExpectationRowsMatchMetricsJson) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  const std::string page = report_of(run);
  const nlohmann::json metrics = read_json(run / "metrics.json");
  const nlohmann::json bounds = read_json(run / "run.json")["expectations"];
  ASSERT_EQ(bounds.size(), 3u);
  int failed = 0;
  for (const auto& b : bounds) {
    const std::string metric = b["metric"].get<std::string>();
    bool fails = false;
    for (const auto& f : metrics["expectations"]["failures"])
      fails = fails || f.get<std::string>().rfind(metric + " ", 0) == 0;
    failed += fails;
    EXPECT_EQ(result_of(page, metric), fails ? "FAIL" : "PASS") << metric;
  }
  EXPECT_EQ(failed, 1);
  EXPECT_EQ(metrics["expectations"]["passed"], false);
  EXPECT_NE(page.find(">FAILED<"), std::string::npos);
  for (const auto& f : metrics["expectations"]["failures"])
    EXPECT_NE(page.find(html_escaped(f.get<std::string>())), std::string::npos) << f;
  // The header and metrics tables.
  EXPECT_NE(page.find("can_fault"), std::string::npos);
  EXPECT_NE(page.find("Report fixture: node 2 loses power"), std::string::npos);
  EXPECT_NE(page.find("power_loss node 2"), std::string::npos);
  EXPECT_NE(page.find("iae_contour_cm"), std::string::npos);
  EXPECT_NE(page.find("iae_velocity_pulse"), std::string::npos);
  EXPECT_NE(page.find("stop_reason"), std::string::npos);
  EXPECT_NE(page.find("node_missing"), std::string::npos);
}

TEST(RunReport, PlotsAreValidPngsThatExist) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  const std::string page = report_of(run);
  const std::vector<std::string> images = images_of(page);
  for (const char* name : {"plots/path.png", "plots/errors.png", "plots/wheels.png", "plots/bus.png"})
    EXPECT_NE(std::find(images.begin(), images.end(), name), images.end()) << name;
  for (const auto& img : images) {
    EXPECT_GT(fs::file_size(run / img), 1000u) << img;
    EXPECT_TRUE(is_png(run / img)) << img;
  }
  // Nothing of the temporary files is left.
  for (const auto& e : fs::recursive_directory_iterator(run))
    EXPECT_EQ(e.path().filename().string().find(".part"), std::string::npos) << e.path();
}

TEST(RunReport, LinksOnlyFilesThatExist) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  fs::remove(run / "master.log");
  const std::string page = report_of(run);
  const std::vector<std::string> links = links_of(page);
  for (const auto& l : links) {
    EXPECT_EQ(l.find("//"), std::string::npos) << "external or absolute link: " << l;
    EXPECT_TRUE(fs::is_regular_file(run / l)) << "dangling link: " << l;
  }
  for (const char* name : {"bus-can.pcap", "trajectory.csv", "metrics.json", "events.log", "bus.csv", "run.json"})
    EXPECT_NE(std::find(links.begin(), links.end(), name), links.end()) << name;
  EXPECT_EQ(std::find(links.begin(), links.end(), "master.log"), links.end());
  EXPECT_EQ(std::find(links.begin(), links.end(), "video.mp4"), links.end());
  EXPECT_EQ(page.find("<video"), std::string::npos);
  EXPECT_NE(page.find("Absent: master.log"), std::string::npos);
  EXPECT_EQ(page.find("<script"), std::string::npos);
  // The events table holds every line of events.log, faults among them.
  EXPECT_EQ(count_of(page, "<td>fault</td>"), 2u);

  // A video, once there, is embedded and linked.
  write_file(run / "video.mp4", "not really a video");
  const std::string with_video = report_of(run);
  EXPECT_NE(with_video.find(R"(<video controls preload="metadata" src="video.mp4">)"), std::string::npos);
  // Issue 18: what a person wants first — the verdict, the video, the headline plots, the
  // expectations — then the detailed tables, folded (<details>, no script).
  const auto at = [&](const std::string& part) {
    const auto p = with_video.find(part);
    EXPECT_NE(p, std::string::npos) << part;
    return p;
  };
  const auto verdict = at("class=\"banner"), video = at("<video"), glance = at("<h2>At a glance</h2>"),
             expect = at("<h2>Expectations</h2>"), metrics = at("<summary><h2>Metrics</h2></summary>"),
             events = at("<summary><h2>Events</h2></summary>");
  EXPECT_LT(verdict, video);
  EXPECT_LT(video, glance);
  EXPECT_LT(glance, expect);
  EXPECT_LT(expect, metrics);
  EXPECT_LT(metrics, events);
  EXPECT_EQ(with_video.find("<script"), std::string::npos);
}

// A video written elsewhere (run --video FILE, render --out FILE) is the run's video: the
// report said "Absent: video.mp4" and embedded nothing (found in review).
TEST(RunReport, AVideoWrittenElsewhereIsEmbeddedByItsRelativePath) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  write_file(tmp / "the run.mp4", "not really a video");
  const ReportResult r = write_run_report(run.string(), tools(), (tmp / "the run.mp4").string());
  ASSERT_TRUE(r.ok) << r.error;
  const std::string page = read_bytes(run / "report.html");
  EXPECT_NE(page.find(R"(<video controls preload="metadata" src="../the%20run.mp4">)"), std::string::npos) << page;
  EXPECT_EQ(page.find("video.mp4 (not rendered"), std::string::npos);
}

// An interrupted run's plots end at its last sample: a fault planned after it is not shaded,
// and one that began before it ends there. The time axis ran on to the planned duration and
// shaded faults that never happened (found in review).
TEST(RunReport, FaultSpansEndAtTheLastRecordedSample) {
  const std::string check =
      tools().python + " -c \"import sys; sys.path.insert(0, '" + tools().scripts_dir + "'); import run_report as r; "
      "run = {'duration_s': 3.5, 'faults': [{'at_s': 0.5, 'duration_s': 0.2}, {'at_s': 1.0}, {'at_s': 2.5}]}; "
      "end = r.run_end(run, {'t': [0.0, 0.7, 1.42]}, {}); "
      "spans = r.fault_spans(run, end); "
      "sys.exit(0 if end == 1.42 and spans == [(0.5, 0.7), (1.0, 1.42)] else print(end, spans) or 1)\"";
  EXPECT_EQ(std::system(check.c_str()), 0);
}

TEST(RunReport, SameInputSameOutput) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  const std::string first = report_of(run);
  const std::string plot = read_bytes(run / "plots" / "errors.png");
  const std::string second = report_of(run);
  EXPECT_EQ(first, second);
  EXPECT_EQ(plot, read_bytes(run / "plots" / "errors.png"));
}

TEST(RunReport, InterruptedRunSaysSo) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  nlohmann::json m = read_json(run / "metrics.json");
  m["interrupted"] = true;
  m["sim_time_s"] = 1.23;
  m["expectations"] = {{"passed", false}, {"failures", {"interrupted at t = 1.230 s: expectations not evaluated"}}};
  write_file(run / "metrics.json", m.dump(2));
  // A partial CSV: 100 rows and half a line.
  const std::vector<std::string> lines = omnitwin::testing::lines_of(read_bytes(run / "trajectory.csv"));
  std::string partial;
  for (size_t i = 0; i <= 100; ++i) partial += lines[i] + "\n";
  partial += lines[101].substr(0, lines[101].size() / 2);
  write_file(run / "trajectory.csv", partial);
  fs::remove(run / "bus.csv");

  const std::string page = report_of(run);
  EXPECT_NE(page.find(">INTERRUPTED<"), std::string::npos);
  EXPECT_NE(page.find("last line incomplete"), std::string::npos);
  EXPECT_EQ(result_of(page, "platform.final_error_cm"), "NOT EVALUATED");
  EXPECT_EQ(count_of(page, R"(class="PASS")"), 0u);
  EXPECT_TRUE(is_png(run / "plots" / "path.png"));
  EXPECT_FALSE(fs::exists(run / "plots" / "bus.png"));  // no bus.csv, no bus plot
}

// A signal after the run loop's end (while the video or the report was made) leaves the run
// and its records whole and its expectations judged: the page said the records were partial,
// marked every bound NOT EVALUATED and then "Run verdict: passed" (found in review).
TEST(RunReport, InterruptedWhileTheOutputsWereMadeJudgesTheWholeRun) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  nlohmann::json m = read_json(run / "metrics.json");
  m["interrupted"] = true;
  m["interrupted_phase"] = "outputs";
  write_file(run / "metrics.json", m.dump(2));
  const std::string page = report_of(run);
  EXPECT_NE(page.find(">INTERRUPTED<"), std::string::npos);
  EXPECT_NE(page.find("the run and its records are whole"), std::string::npos) << page;
  EXPECT_NE(page.find("the video may stop before the run's end"), std::string::npos);
  EXPECT_EQ(page.find("NOT EVALUATED"), std::string::npos);
  EXPECT_EQ(count_of(page, R"(class="PASS")"), 2u);  // the fixture's bounds, judged
  EXPECT_EQ(count_of(page, R"(class="FAIL")"), 1u);
  EXPECT_NE(page.find("Run verdict (metrics.json): <b>INTERRUPTED</b>"), std::string::npos);
  // Even when every bound held, the page never calls such a run passed.
  m["expectations"] = {{"passed", true}, {"failures", nlohmann::json::array()}};
  write_file(run / "metrics.json", m.dump(2));
  const std::string all_met = report_of(run);
  EXPECT_EQ(all_met.find("<b>passed</b>"), std::string::npos);
  EXPECT_EQ(all_met.find(">PASSED<"), std::string::npos);
  EXPECT_NE(all_met.find("the expectations alone: met"), std::string::npos);
}

// Every metric group and top-level figure of metrics.json is on the page: `drives` (when the
// drives stopped, how many ended running) and `stopped_by` were left out (found in review).
TEST(RunReport, EveryMetricGroupAndRunFigureIsShown) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  nlohmann::json m = read_json(run / "metrics.json");
  m["drives"] = {{"all_running_at_s", 0.02}, {"running_at_end", 3}, {"stopped_at_s", 2.02}, {"faults", 1}};
  m["stopped_by"] = "a test";
  m["a_newer_group"] = {{"some_figure", 42}};
  write_file(run / "metrics.json", m.dump(2));
  const std::string page = report_of(run);
  for (const char* what : {"<h3>Drives</h3>", "running_at_end", "stopped_at_s", "<h3>a_newer_group</h3>",
                           "some_figure", "stopped_by", "a test"})
    EXPECT_NE(page.find(what), std::string::npos) << what;
}

// The GL that drew the video is said under it when the process that made it passes it on.
TEST(RunReport, SaysWhichGlDrewTheVideo) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  write_file(run / "video.mp4", "not really a video");
  const ReportResult r = write_run_report(run.string(), tools(), "", "Vendor / A GPU / OpenGL 4.6 (EGL device)");
  ASSERT_TRUE(r.ok) << r.error;
  const std::string page = read_bytes(run / "report.html");
  EXPECT_NE(page.find("Video drawn by Vendor / A GPU / OpenGL 4.6 (EGL device)."), std::string::npos);
  EXPECT_EQ(report_of(run).find("Video drawn by"), std::string::npos);  // not known: not said
}

// Each bus's capture and master files are expected: a canopen or EtherCAT run without them
// said nothing (only bus can's were known; found in review).
TEST(RunReport, EachBusExpectsItsOwnCaptureAndMasterFiles) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  nlohmann::json r = read_json(run / "run.json");
  r["bus"] = "ethercat";
  r["master_kind"] = "omni-master";
  write_file(run / "run.json", r.dump(2));
  const std::string page = report_of(run);
  EXPECT_NE(page.find("Absent: bus-ethercat.pcap, master-stats.json"), std::string::npos) << page;
}

// A run whose master the twin did not start (`omnitwin twin`) leaves no master.log or
// master-stats.json, and its report must not call them absent; the built-in master's run
// must (found in review).
TEST(RunReport, MasterFilesAreExpectedOnlyFromAMasterTheTwinStarted) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  fs::remove(run / "master.log");
  nlohmann::json r = read_json(run / "run.json");
  r["bus"] = "canopen";
  r["master_kind"] = "external";
  write_file(run / "run.json", r.dump(2));
  EXPECT_EQ(report_of(run).find("Absent: master"), std::string::npos);
  r["master_kind"] = "command";
  write_file(run / "run.json", r.dump(2));
  EXPECT_NE(report_of(run).find("Absent: master.log, video.mp4"), std::string::npos);
  r["master_kind"] = "omni-master";
  write_file(run / "run.json", r.dump(2));
  EXPECT_NE(report_of(run).find("Absent: master.log, master-stats.json, video.mp4"), std::string::npos);
}

// The frame rates of bus.csv run to the end of the run: the last, partial window was never
// drawn, so a loss in the last second did not show (found in review).
TEST(RunReport, FrameRatesIncludeTheLastPartialWindow) {
  const std::string check =
      tools().python + " -c \"import sys; sys.path.insert(0, '" + tools().scripts_dir + "'); import run_report as r; "
      "t = [i * 0.05 for i in range(113)]; c = [min(i, 101) * 10 for i in range(113)]; "
      "ends, rates = r.windowed_rates(t, c); "
      "ok = abs(ends[-1] - 5.6) < 1e-9 and rates[-1] < 20 and abs(rates[1] - 200) < 1e-6; "
      "sys.exit(0 if ok else print(ends[-3:], rates[-3:]) or 1)\"";
  EXPECT_EQ(std::system(check.c_str()), 0);
}

TEST(RunReport, RunWithoutMetricsSaysSo) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  fs::remove(run / "metrics.json");
  const std::string page = report_of(run);
  EXPECT_NE(page.find("NO METRICS"), std::string::npos);
  EXPECT_NE(page.find("metrics.json is absent"), std::string::npos);
  EXPECT_TRUE(is_png(run / "plots" / "wheels.png"));
}

TEST(RunReport, OlderRunWithoutRunJsonOrBusCsv) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  fs::remove(run / "run.json");
  fs::remove(run / "bus.csv");
  const std::string page = report_of(run);
  EXPECT_NE(page.find("run.json is absent"), std::string::npos);
  EXPECT_NE(page.find("bus.csv is absent"), std::string::npos);
  EXPECT_NE(page.find("platform.final_error_cm = "), std::string::npos);  // the run's own failures
  EXPECT_TRUE(is_png(run / "plots" / "errors.png"));
}

TEST(RunReport, MissingOrInvalidRunDirIsAnError) {
  TempDir tmp("omnitwin-report");
  const ReportResult missing = write_run_report((tmp / "nope").string(), tools());
  EXPECT_FALSE(missing.ok);
  EXPECT_NE(missing.error.find("nope"), std::string::npos) << missing.error;

  fs::create_directory(tmp / "empty");
  const ReportResult empty = write_run_report((tmp / "empty").string(), tools());
  EXPECT_FALSE(empty.ok);
  EXPECT_NE(empty.error.find("not a run directory"), std::string::npos) << empty.error;
  EXPECT_FALSE(fs::exists(tmp / "empty" / "report.html"));
}

TEST(RunReport, MissingToolsAreAnError) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  ReportTools no_python = tools();
  no_python.python = (tmp / "no-python3").string();
  const ReportResult a = write_run_report(run.string(), no_python);
  EXPECT_FALSE(a.ok);
  EXPECT_NE(a.error.find("no-python3"), std::string::npos) << a.error;

  ReportTools no_scripts = tools();
  no_scripts.scripts_dir = tmp.path().string();
  const ReportResult b = write_run_report(run.string(), no_scripts);
  EXPECT_FALSE(b.ok);
  EXPECT_NE(b.error.find("run_report.py"), std::string::npos) << b.error;

  // A script that fails says why (its last stderr line) and its exit status.
  fs::create_directory(tmp / "scripts");
  write_file(tmp / "scripts" / "run_report.py", "import sys\nsys.stderr.write('boom: no luck\\n')\nsys.exit(3)\n");
  ReportTools failing = tools();
  failing.scripts_dir = (tmp / "scripts").string();
  const ReportResult c = write_run_report(run.string(), failing);
  EXPECT_FALSE(c.ok);
  EXPECT_NE(c.error.find("exit 3"), std::string::npos) << c.error;
  EXPECT_NE(c.error.find("boom: no luck"), std::string::npos) << c.error;
  EXPECT_FALSE(fs::exists(run / "report.html"));
}

TEST(RunReport, HungScriptIsKilledAtTheTimeout) {
  TempDir tmp("omnitwin-report");
  const fs::path run = copy_fixture(tmp);
  fs::create_directory(tmp / "scripts");
  write_file(tmp / "scripts" / "run_report.py", "import time\ntime.sleep(60)\n");
  ReportTools hung = tools();
  hung.scripts_dir = (tmp / "scripts").string();
  hung.timeout_s = 1;
  const ReportResult r = write_run_report(run.string(), hung);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.error.find("did not finish within 1 s"), std::string::npos) << r.error;
  EXPECT_LT(r.seconds, 10.0);
}

// One check-index entry for a run directory with a (stand-in) report.html.
nlohmann::json entry(const fs::path& run_dir, const std::string& name, bool passed) {
  fs::create_directories(run_dir);
  write_file(run_dir / "report.html", "<html></html>");
  nlohmann::json metrics = {{"real_time_factor", 21.5},
                            {"platform", {{"final_error_cm", passed ? 0.25 : 7.5}, {"iae_contour_cm", 845.5}}},
                            {"bus", {{"name", "can"}, {"dropouts", 17}}}};
  nlohmann::json failures = nlohmann::json::array();
  if (!passed) failures.push_back("platform.final_error_cm = 7.5 > max 0.5");
  return {{"scenario", name},       {"file", "tests/regression/" + name + ".yaml"},
          {"run_dir", run_dir.string()}, {"exit_code", passed ? 0 : 1},
          {"passed", passed},       {"failures", failures},
          {"metrics", metrics}};
}

TEST(CheckIndex, CountsAndLinksRelativeToTheIndex) {
  TempDir tmp("omnitwin-index");
  const nlohmann::json summary = {
      {"title", "omnitwin check"},
      {"results", {entry(tmp / "runs" / "good_one", "good_one", true), entry(tmp / "runs" / "bad_one", "bad_one", false)}}};
  const fs::path index = tmp / "html" / "index.html";
  const ReportResult r = write_check_index(index.string(), summary, tools());
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_EQ(r.path, index.string());
  const std::string page = read_bytes(index);
  EXPECT_NE(page.find("1 passed, 1 failed"), std::string::npos);
  EXPECT_NE(page.find("platform.final_error_cm = 7.5 &gt; max 0.5"), std::string::npos);
  EXPECT_NE(page.find("7.5"), std::string::npos);
  EXPECT_NE(page.find("845.5"), std::string::npos);
  EXPECT_NE(page.find("21.5"), std::string::npos);
  const std::vector<std::string> links = links_of(page);
  ASSERT_EQ(links.size(), 2u);
  for (const auto& l : links) {
    EXPECT_EQ(l.rfind("../runs/", 0), 0u) << l;
    EXPECT_TRUE(fs::is_regular_file(index.parent_path() / l)) << l;
  }
  // The summary's temporary file is gone.
  for (const auto& e : fs::directory_iterator(index.parent_path()))
    EXPECT_EQ(e.path().filename(), "index.html") << e.path();
}

TEST(CheckIndex, BadToolsOrSummaryAreErrors) {
  TempDir tmp("omnitwin-index");
  ReportTools no_python = tools();
  no_python.python = (tmp / "no-python3").string();
  const nlohmann::json summary = {{"title", "t"}, {"results", nlohmann::json::array()}};
  EXPECT_FALSE(write_check_index((tmp / "index.html").string(), summary, no_python).ok);

  const ReportResult bad = write_check_index((tmp / "index.html").string(), {{"title", "t"}}, tools());
  EXPECT_FALSE(bad.ok);
  EXPECT_NE(bad.error.find("results"), std::string::npos) << bad.error;

  const ReportResult none = write_check_index((tmp / "index.html").string(), summary, tools());
  ASSERT_TRUE(none.ok) << none.error;
  EXPECT_NE(read_bytes(tmp / "index.html").find("0 passed, 0 failed"), std::string::npos);
}

}  // namespace
}  // namespace omnitwin::media
