// Integration tests of the run's outputs through the real command line (twin/main.cpp,
// twin/run_outputs.cpp, twin/dds_observer.hpp), each side a real process:
//  - DDS: `omnitwin run --dds` publishes on loopback and a separate `omnitwin echo` process
//    receives platform states whose poses equal trajectory.csv's rows at the same sim time,
//    and the run's start and end events; a bad DDS interface is bad input (exit 2);
//  - video: `run --video FILE` writes an H.264 yuv420p MP4 with one frame per 1/fps of sim
//    time (ffprobe); `render RUN_DIR` renders a recorded run again; a CAN run stopped by
//    SIGINT half-way still leaves a playable MP4 of the part recorded, a complete CSV, a
//    capture tshark decodes, and metrics marked interrupted;
//  - report: `run` writes report.html; `check` writes one per run and an index page that
//    counts "1 passed, 1 failed" and links both reports.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "tests/bus_emulators/small_tmpfs.hpp"
#include "tests/support/dds_domain.hpp"
#include "tests/twin/cli_support.hpp"

namespace omnitwin::twin {
namespace {

using namespace omnitwin::twin::cli;
using omnitwin::testing::lines_of;

// A DDS domain of our own (parallel ctest processes must not hear each other).
int own_domain(int k) { return omnitwin::testing::owned_dds_domain(k); }

// ffprobe's view of a video stream: codec, pixel format, frames decoded, duration.
struct Probe {
  bool ok = false;
  std::string codec, pix_fmt;
  long frames = 0;
  double duration_s = 0;
  std::string raw;
};

Probe probe(const fs::path& file, const fs::path& io) {
  Probe p;
  const fs::path out = io / "ffprobe.json";
  const std::string cmd = "ffprobe -v error -count_frames -select_streams v:0 -show_entries "
                          "stream=codec_name,pix_fmt,nb_read_frames -show_entries format=duration -of json '" +
                          file.string() + "' > '" + out.string() + "' 2>&1";
  if (std::system(cmd.c_str()) != 0) {
    p.raw = read_bytes(out);
    return p;
  }
  p.raw = read_bytes(out);
  const nlohmann::json j = nlohmann::json::parse(p.raw);
  const auto& st = j["streams"][0];
  p.codec = st.value("codec_name", "");
  p.pix_fmt = st.value("pix_fmt", "");
  p.frames = std::stol(st.value("nb_read_frames", "0"));
  p.duration_s = std::stod(j["format"].value("duration", "0"));
  p.ok = true;
  return p;
}

// trajectory.csv rows by their time column, as text → numbers (first 7 columns).
std::map<long, std::array<double, 7>> trajectory_by_ms(const fs::path& csv) {
  std::map<long, std::array<double, 7>> rows;
  const auto lines = lines_of(read_bytes(csv));
  for (std::size_t i = 1; i < lines.size(); ++i) {
    std::istringstream in(lines[i]);
    std::array<double, 7> v{};
    std::string cell;
    for (double& x : v) {
      std::getline(in, cell, ',');
      x = std::stod(cell);
    }
    rows[std::lround(v[0] * 1000)] = v;
  }
  return rows;
}

// A small, fast video for tests (the scenario's outputs section, as YAML).
const char* kSmallVideo = "outputs.video={enabled: true, width: 160, height: 120, fps: 10}";

class CliOutputs : public CliTest {};

// A separate `omnitwin echo` process on loopback receives the run's platform states; each
// one's pose equals the trajectory row recorded at the same simulated time (to the CSV's
// 10 significant digits), and the run's start and end events come through. The run waits
// for the echo's reader (outputs.dds.wait_for_readers), so the first state is received and
// nearly all of them arrive (best effort, loopback). Without the wait, a lockstep run had
// published a third of its states before the echo was discovered under a loaded -j2 ctest
// (the samples before matching are not delivered: 270 and 289 of 351 in two failures).
TEST_F(CliOutputs, EchoInAnotherProcessReceivesTheRunsStates) {
  const std::string domain = std::to_string(own_domain(0));
  Child echo(omnitwin_binary(), {"echo", "--json", "--domain", domain, "--interface", "lo", "--timeout", "4"}, work(),
             io(), "echo-");
  const fs::path out = dir_ / "run";
  const Finished f = run({"run", test_scenario("run_short_line.yaml"), "--out", out.string(), "--no-progress", "--dds",
                          "--set", "outputs.dds.domain=" + domain, "--set", "outputs.dds.interface=lo", "--set",
                          "outputs.dds.wait_for_readers=1"});
  ASSERT_EQ(f.code, 0) << f.err;
  EXPECT_TRUE(contains(f.out, "DDS: 351 states published")) << f.out;
  ASSERT_EQ(echo.wait(20s), 0) << echo.err();
  const auto rows = trajectory_by_ms(out / "trajectory.csv");
  std::size_t states = 0;
  double first_t = -1;
  std::vector<std::string> events;
  for (const std::string& line : lines_of(echo.out())) {
    const nlohmann::json j = nlohmann::json::parse(line);
    if (j["topic"] == "run_events") events.push_back(j["kind"].get<std::string>());
    if (j["topic"] != "platform_state") continue;
    if (states++ == 0) first_t = j["t"].get<double>();
    const auto it = rows.find(std::lround(j["t"].get<double>() * 1000));
    ASSERT_NE(it, rows.end()) << line;
    EXPECT_NEAR(j["x"].get<double>(), it->second[4], 1e-9 + 1e-9 * std::abs(it->second[4])) << line;
    EXPECT_NEAR(j["y"].get<double>(), it->second[5], 1e-9 + 1e-9 * std::abs(it->second[5])) << line;
    EXPECT_NEAR(j["phi"].get<double>(), it->second[6], 1e-9 + 1e-9 * std::abs(it->second[6])) << line;
  }
  EXPECT_GE(states, 345u) << "of 351 published";
  EXPECT_EQ(first_t, 0.0) << "the run waited for the echo's reader";
  EXPECT_TRUE(contains(f.err, "DDS: waiting up to 10 s for 1 reader(s) of a state topic")) << f.err;
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.front(), "start");
  EXPECT_EQ(events.back(), "end");
}

// A run whose records meet a full disk ends with exit 3; on DDS its verdict must say so. The
// verdict and the end event went out before the records were closed and metrics.json written,
// and a reader got "expectations passed" for that run (found in review).
TEST_F(CliOutputs, TheVerdictOnDdsIsTheRunsFinalOneAfterItsRecords) {
  omnitwin::testing::SmallTmpfs disk("16k");
  if (!disk.mounted()) GTEST_SKIP() << disk.skip_reason();
  const std::string domain = std::to_string(own_domain(1));
  Child echo(omnitwin_binary(), {"echo", "--json", "--domain", domain, "--interface", "lo", "--timeout", "4"}, work(),
             io(), "echo-");
  const Finished f = run({"run", test_scenario("run_short_line.yaml"), "--out", (disk / "run").string(),
                          "--no-progress", "--no-video", "--no-report", "--dds", "--set", "outputs.dds.domain=" + domain,
                          "--set", "outputs.dds.interface=lo", "--set", "outputs.dds.wait_for_readers=1", "--set",
                          "duration=0.3"});
  ASSERT_EQ(f.code, 3) << f.out << f.err;
  echo.wait(20s);
  std::vector<nlohmann::json> events;
  for (const std::string& line : lines_of(echo.out())) {
    const nlohmann::json j = nlohmann::json::parse(line);
    if (j["topic"] == "run_events") events.push_back(j);
  }
  ASSERT_FALSE(events.empty()) << echo.out();
  bool said_failed = false;
  for (const nlohmann::json& e : events) {
    EXPECT_FALSE(e["kind"] == "expectation" && e["text"] == "passed") << e.dump();
    said_failed = said_failed || (e["kind"] == "expectation" && e["text"] == "failed");
  }
  EXPECT_TRUE(said_failed) << echo.out();
  EXPECT_NE(events.back()["text"].get<std::string>(), "expectations passed (0 failures)") << echo.out();
}

// A negative --count wrapped to 2^64 - 1 and a negative --timeout meant "never" (found in
// review): both are bad usage now.
TEST_F(CliOutputs, EchoRefusesANegativeCountOrTimeout) {
  for (const char* opt : {"--count", "--timeout"}) {
    const Finished f = run({"echo", opt, "-1"});
    EXPECT_EQ(f.code, 2) << opt << ": " << f.err;
    EXPECT_TRUE(contains(f.err, std::string(opt) + ": must not be negative")) << f.err;
  }
}

// A DDS interface that does not exist is bad input: exit 2, one line naming outputs.dds,
// and no run directory.
TEST_F(CliOutputs, UnknownDdsInterfaceIsBadInput) {
  const fs::path out = dir_ / "never";
  const Finished f = run({"run", test_scenario("run_short_line.yaml"), "--out", out.string(), "--no-progress", "--dds",
                          "--set", "outputs.dds.interface=nosuchif0"});
  EXPECT_EQ(f.code, 2) << f.err;
  EXPECT_TRUE(contains(f.err, "outputs.dds")) << f.err;
  EXPECT_FALSE(fs::exists(out));
}

// run --video FILE: H.264, yuv420p, floor(3.5 s · 10 fps) + 1 = 36 frames, 3.6 s; render
// RUN_DIR makes the same video again from the records alone.
TEST_F(CliOutputs, RunVideoAndRenderAgree) {
  const fs::path out = dir_ / "run";
  const fs::path mp4 = dir_ / "v.mp4";
  const Finished f = run({"run", test_scenario("run_short_line.yaml"), "--out", out.string(), "--no-progress", "--video",
                          mp4.string(), "--set", kSmallVideo});
  ASSERT_EQ(f.code, 0) << f.err;
  EXPECT_TRUE(contains(f.out, mp4.string() + " (36 frames")) << f.out;
  // It says which GL drew the frames (the default backend is OSMesa).
  EXPECT_TRUE(contains(f.out, "    drawn by ") && contains(f.out, "(OSMesa)\n")) << f.out;
  const Probe p = probe(mp4, io());
  ASSERT_TRUE(p.ok) << p.raw;
  EXPECT_EQ(p.codec, "h264");
  EXPECT_EQ(p.pix_fmt, "yuv420p");
  EXPECT_EQ(p.frames, 36);
  EXPECT_NEAR(p.duration_s, 3.6, 0.05);
  const fs::path again = dir_ / "again.mp4";
  const Finished r = run({"render", out.string(), "--out", again.string(), "--width", "160", "--height", "120", "--fps",
                          "10"});
  ASSERT_EQ(r.code, 0) << r.err;
  const Probe q = probe(again, io());
  ASSERT_TRUE(q.ok) << q.raw;
  EXPECT_EQ(q.frames, 36);
  const Finished bad = run({"render", (dir_ / "nothing").string()});
  EXPECT_EQ(bad.code, 2);
  EXPECT_TRUE(contains(bad.err, "not a run directory")) << bad.err;
  // A malformed record is bad input too (exit 2, it was 3), naming file and line; a malformed
  // bus.csv only loses the overlay's bus line (it failed the video).
  std::ofstream(out / "bus.csv", std::ios::app) << "1.0,garbage\n";
  const Finished no_bus = run({"render", out.string(), "--out", again.string(), "--width", "160", "--height", "120",
                               "--fps", "10"});
  EXPECT_EQ(no_bus.code, 0) << no_bus.err;
  EXPECT_TRUE(contains(no_bus.out + no_bus.err, "bus.csv")) << no_bus.out << no_bus.err;
  std::ofstream(out / "trajectory.csv", std::ios::app) << "1.0,garbage\n";
  const Finished torn = run({"render", out.string(), "--out", again.string()});
  EXPECT_EQ(torn.code, 2) << torn.err;
  EXPECT_TRUE(contains(torn.err, "trajectory.csv:")) << torn.err;
}

// SIGINT half-way through a long lockstep CAN run: exit 3, metrics say interrupted, the CSV
// is complete up to the stop, the video of the part recorded is playable with one frame per
// 1/fps of the simulated time reached, and the capture decodes in tshark with every frame.
TEST_F(CliOutputs, SigintHalfWayLeavesPlayableVideo) {
  const fs::path out = dir_ / "run";
  Child c({"run", test_scenario("run_long_line.yaml"), "--bus", "can", "--set", "bus.transport=udp:239.74.163.2:47616",
           "--out", out.string(), "--no-progress", "--set", "outputs.video={enabled: true, width: 160, height: 120, fps: 5}"},
          work(), io());
  // Wait until a few seconds of the run are recorded, then interrupt.
  const fs::path part = out / ".trajectory.csv.part";
  for (int i = 0; i < 600 && !(fs::exists(part) && fs::file_size(part) > 300'000); ++i) std::this_thread::sleep_for(10ms);
  c.signal(SIGINT);
  ASSERT_EQ(c.wait(180s), 3) << c.err();
  const nlohmann::json m = nlohmann::json::parse(read_bytes(out / "metrics.json"));
  EXPECT_TRUE(m["interrupted"].get<bool>());
  const double sim_s = m["sim_time_s"].get<double>();
  EXPECT_GT(sim_s, 1.0);
  EXPECT_LT(sim_s, 100.0);
  const auto rows = trajectory_by_ms(out / "trajectory.csv");
  ASSERT_FALSE(rows.empty());
  const Probe p = probe(out / "video.mp4", io());
  ASSERT_TRUE(p.ok) << p.raw;
  EXPECT_EQ(p.codec, "h264");
  // Frames at k/5 s up to the last row, and one more at the last row's t unless it fell on one.
  const double last_t = rows.rbegin()->second[0];
  const long steps = static_cast<long>(std::floor(last_t * 5 + 1e-6));
  EXPECT_EQ(p.frames, steps + 1 + (steps / 5.0 < last_t - 1e-9 ? 1 : 0)) << "last row t = " << last_t;
  // The capture: every frame the bus completed, none malformed.
  if (std::system("command -v tshark >/dev/null 2>&1") != 0) GTEST_SKIP() << "tshark is not installed";
  const std::string pcap = (out / "bus-can.pcap").string();
  const fs::path ids = dir_ / "ids.txt", bad = dir_ / "bad.txt";
  ASSERT_EQ(std::system(("tshark -r " + pcap + " -T fields -e can.id > " + ids.string() + " 2>/dev/null").c_str()), 0);
  ASSERT_EQ(std::system(("tshark -r " + pcap + " -Y _ws.malformed > " + bad.string() + " 2>/dev/null").c_str()), 0);
  EXPECT_EQ(lines_of(read_bytes(ids)).size(), m.at("bus").at("frames").get<std::size_t>());
  EXPECT_TRUE(read_bytes(bad).empty()) << read_bytes(bad);
}

}  // namespace
}  // namespace omnitwin::twin
