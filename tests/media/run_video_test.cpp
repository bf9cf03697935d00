// Tests media/run_video: a small run directory (run.json, platform.xml from the default
// parameters, 2 s of trajectory.csv moving 0.3 m along x, bus.csv) becomes an MP4 with one
// frame per 1/fps of sim time that ffprobe reads back; the picture follows the recorded
// pose; a stop request gives a shorter playable file, also when stop requests keep coming
// while it is finalised and when they are two SIGINTs 50 ms apart; missing or malformed run
// files, an unwritable output and a full disk are clear errors naming the file, after which
// nothing (not even an older video) is under the final name. Any MuJoCo warning fails a test.
#include "media/run_video.hpp"

#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "tests/bus_emulators/small_tmpfs.hpp"

#include "physics/platform_mjcf.hpp"
#include "tests/media/media_probe.hpp"
#include "tests/support/mujoco_fixture.hpp"
#include "tests/support/temp_dir.hpp"

namespace omnitwin::media {
namespace {

namespace fs = std::filesystem;
using omnitwin::media::testing::decode_frame_rgb;
using omnitwin::media::testing::probe;

constexpr double kDuration = 2.0, kPeriod = 0.01, kDistance = 0.3;

std::string trajectory_header() {
  std::string h = "t,ref_x,ref_y,ref_phi,x,y,phi,odom_x,odom_y,odom_phi,vx,vy,wz,cmd_vx,cmd_vy,cmd_wz";
  for (int i = 1; i <= 4; ++i)
    for (const char* c : {"cmd_rad_s", "speed_rad_s", "angle_rad", "count", "cmd_counts", "meas_counts",
                          "dac_code", "setpoint_rad_s", "torque_nm"})
      h += ",w" + std::to_string(i) + "_" + c;
  return h;
}

// One row: the platform at x = 0.3 m * t / 2 s, wheels turning, a master command of nan.
std::string trajectory_row(double t) {
  const double v = kDistance / kDuration, x = v * t;
  std::string r = std::to_string(t) + "," + std::to_string(x) + ",0,0," + std::to_string(x) + ",0,0," +
                  std::to_string(x) + ",0,0," + std::to_string(v) + ",0,0,nan,nan,nan";
  for (int i = 0; i < 4; ++i)
    r += ",3.5,3.5," + std::to_string(3.5 * t) + ",0,0,0,0,3.5,0.01";
  return r;
}

// A complete run directory of kDuration seconds.
class RunVideo : public omnitwin::testing::MujocoTest {
 protected:
  void SetUp() override {
    MujocoTest::SetUp();
    std::ofstream(dir_ / "run.json")
        << R"({"format": 1, "scenario": "media_test", "bus": "can", "clock": "lockstep",
               "model": "platform.xml", "control_period_s": 0.01, "physics_timestep_s": 0.001,
               "duration_s": 2.0, "start_pose": [0, 0, 0],
               "faults": [{"kind": "power_loss", "target": "node 2", "at_s": 0.5, "duration_s": 0.5,
                           "text": "power_loss node 2"}],
               "expectations": []})";
    std::ofstream(dir_ / "platform.xml") << physics::platform_mjcf(physics::PlatformParams{});
    std::ofstream traj(dir_ / "trajectory.csv");
    std::ofstream bus(dir_ / "bus.csv");
    traj << trajectory_header() << "\n";
    bus << "t,frames_tx,frames_rx,dropouts,errors,load,active_faults,s1_state,s2_state,s3_state,s4_state\n";
    for (int k = 0; k <= static_cast<int>(std::lround(kDuration / kPeriod)); ++k) {
      const double t = k * kPeriod;
      traj << trajectory_row(t) << "\n";
      const bool fault = t >= 0.5 && t < 1.0;
      bus << t << "," << 5 * k << "," << 5 * k << ",0,0,0.3," << fault << ",2," << (fault ? 4 : 2) << ",2,2\n";
    }
  }

  std::string out(const std::string& name = "video.mp4") const { return (dir_ / name).string(); }
  std::string run_dir() const { return dir_.path().string(); }

  static VideoOptions small() {
    VideoOptions o;
    o.width = 160;
    o.height = 120;
    o.fps = 10;
    return o;
  }

  omnitwin::testing::TempDir dir_{"omnitwin-runvideo"};
};

TEST_F(RunVideo, OneFramePerFrameIntervalOfSimTimeFromZeroToTheLastSample) {
  const VideoResult r = render_run(run_dir(), out(), small());
  EXPECT_EQ(r.path, out());
  EXPECT_EQ(r.frames, 21);  // t = 0, 0.1, ..., 2.0
  EXPECT_NEAR(r.duration_s, 2.1, 1e-9);
  EXPECT_FALSE(r.stopped_early);
  EXPECT_GT(r.render_s, 0);
  EXPECT_NE(r.renderer.find(" / OpenGL "), std::string::npos) << r.renderer;
  const auto s = probe(out());
  ASSERT_EQ(s.status, 0);
  EXPECT_EQ(s.codec, "h264");
  EXPECT_EQ(s.pix_fmt, "yuv420p");
  EXPECT_EQ(s.width, 160);
  EXPECT_EQ(s.height, 120);
  EXPECT_EQ(s.frames, 21);
  EXPECT_NEAR(s.duration_s, 2.1, 0.01);
}

TEST_F(RunVideo, PictureFollowsTheRecordedMotion) {
  VideoOptions o = small();
  o.camera = "overview";  // fixed: the platform moves in the picture
  o.overview_inset = false;
  o.overlay = false;  // at 160x120 the text would cover most of the frame
  render_run(run_dir(), out(), o);
  const std::string first = decode_frame_rgb(out(), 0), last = decode_frame_rgb(out(), 20);
  const std::string also_first = decode_frame_rgb(out(), 1);
  ASSERT_EQ(first.size(), 160u * 120u * 3u);
  ASSERT_EQ(last.size(), first.size());
  int moved = 0, early = 0;
  for (size_t i = 0; i < first.size(); ++i) {
    moved += std::abs(first[i] - last[i]) > 40;
    early += std::abs(first[i] - also_first[i]) > 40;
  }
  EXPECT_GT(moved, 100) << "0.3 m of motion shows in the fixed camera";
  EXPECT_LT(early, moved / 3) << "0.015 m of motion shows much less";
}

TEST_F(RunVideo, StopRequestFinalisesAShorterPlayableFile) {
  std::atomic<bool> stop{false};
  VideoOptions o = small();
  o.progress = [&](int done, int total) {
    EXPECT_EQ(total, 21);
    if (done == 8) stop = true;
  };
  const VideoResult r = render_run(run_dir(), out(), o, &stop);
  EXPECT_TRUE(r.stopped_early);
  EXPECT_EQ(r.frames, 8);
  const auto s = probe(out());
  ASSERT_EQ(s.status, 0);
  EXPECT_EQ(s.frames, 8);
  EXPECT_NEAR(s.duration_s, 0.8, 0.01);
}

// Issue 16's signal torture found it: a stop before the first frame left an MP4 of no frames,
// which ffmpeg rejects. Now there is no video at all, and no .part file.
TEST_F(RunVideo, StopRequestBeforeTheFirstFrameLeavesNoVideo) {
  std::atomic<bool> stop{true};
  const VideoResult r = render_run(run_dir(), out(), small(), &stop);
  EXPECT_TRUE(r.stopped_early);
  EXPECT_EQ(r.frames, 0);
  EXPECT_TRUE(r.path.empty());
  EXPECT_FALSE(fs::exists(out()));
  EXPECT_FALSE(fs::exists(dir_ / ".video.mp4.part"));
}

TEST_F(RunVideo, StopRequestsThatKeepComingWhileFinalisingCannotCutTheFile) {
  std::atomic<bool> stop{false};
  std::atomic<bool> done{false};
  VideoOptions o = small();
  o.progress = [&](int frames, int) {
    if (frames == 8) stop = true;
  };
  // A second, third … request: set again and again until render_run has returned.
  std::thread again([&] {
    while (!done) {
      if (stop) stop = true;
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
  });
  const VideoResult r = render_run(run_dir(), out(), o, &stop);
  done = true;
  again.join();
  EXPECT_TRUE(r.stopped_early);
  EXPECT_EQ(r.frames, 8);
  const auto s = probe(out());
  ASSERT_EQ(s.status, 0);
  EXPECT_EQ(s.frames, 8);
  EXPECT_FALSE(fs::exists(dir_ / ".video.mp4.part"));
}

std::atomic<bool> g_stop{false};
void on_sigint(int) { g_stop = true; }

// The reported failure: two SIGINTs 50 ms apart while rendering. A child process renders
// with a handler that only sets the stop flag (no SA_RESTART: system calls see EINTR) and
// says on a pipe when its first frame is done; the parent then sends the two signals.
TEST_F(RunVideo, TwoSigintsFiftyMillisecondsApartLeaveADecodableFile) {
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  VideoOptions o = small();
  o.fps = 100;  // 201 frames: the signals come while it renders
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    struct sigaction sa {};
    sa.sa_handler = on_sigint;
    ::sigaction(SIGINT, &sa, nullptr);
    o.progress = [&](int frames, int) {
      if (frames == 1) (void)!::write(ready[1], "r", 1);
    };
    try {
      const VideoResult r = render_run(run_dir(), out(), o, &g_stop);
      ::_exit(r.stopped_early ? 0 : 2);
    } catch (...) {
      ::_exit(1);
    }
  }
  ::close(ready[1]);
  char c = 0;
  ASSERT_EQ(::read(ready[0], &c, 1), 1);
  ::close(ready[0]);
  ::kill(pid, SIGINT);
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  ::kill(pid, SIGINT);
  int st = 0;
  ::waitpid(pid, &st, 0);
  ASSERT_TRUE(WIFEXITED(st)) << "the renderer died of a signal";
  const int code = WEXITSTATUS(st);
  EXPECT_TRUE(code == 0 || code == 2) << "render_run failed in the child (exit " << code << ")";
  const auto s = probe(out());
  ASSERT_EQ(s.status, 0) << "ffprobe cannot read the file";
  EXPECT_GE(s.frames, 1);
  if (code == 0) {
    EXPECT_LT(s.frames, 201);
  }
  EXPECT_FALSE(fs::exists(dir_ / ".video.mp4.part"));
}

TEST_F(RunVideo, RunWithoutBusCsvStillRenders) {
  fs::remove(dir_ / "bus.csv");
  EXPECT_EQ(render_run(run_dir(), out(), small()).frames, 21);
}

// Runs render_run and returns the error message ("" if it did not throw).
std::string error_of(const std::string& dir, const std::string& file, const VideoOptions& o) {
  try {
    render_run(dir, file, o);
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

TEST_F(RunVideo, MissingRunFilesAreBadRecordsNamingTheFile) {
  for (const char* name : {"trajectory.csv", "platform.xml"}) {
    const fs::path moved = dir_ / (std::string(name) + ".away");
    fs::rename(dir_ / name, moved);
    try {
      render_run(run_dir(), out(), small());
      ADD_FAILURE() << name << ": rendered without it";
    } catch (const BadRunRecord& e) {
      EXPECT_NE(std::string(e.what()).find((dir_ / name).string()), std::string::npos) << name << ": " << e.what();
    }
    fs::rename(moved, dir_ / name);
  }
}

// run.json and bus.csv only feed the overlay (and an older run has neither): one that is
// absent or unreadable costs its overlay line, not the video (it failed the whole video).
TEST_F(RunVideo, AnAbsentOrMalformedRunJsonOrBusCsvStillRenders) {
  fs::remove(dir_ / "run.json");
  EXPECT_EQ(render_run(run_dir(), out(), small()).frames, 21);
  std::ofstream(dir_ / "run.json") << "{ not json";
  std::ofstream(dir_ / "bus.csv") << "t,frames_tx\n0,1\n0.5,zwei\n";
  EXPECT_EQ(render_run(run_dir(), out(), small()).frames, 21);
  std::ofstream(dir_ / "bus.csv") << "frames_tx,frames_rx\n1,1\n";  // no t column
  EXPECT_EQ(render_run(run_dir(), out(), small()).frames, 21);
}

TEST_F(RunVideo, MalformedTrajectoryIsAnErrorWithFileAndLine) {
  std::ofstream(dir_ / "trajectory.csv") << trajectory_header() << "\n"
                                         << trajectory_row(0) << "\n"
                                         << "0.01,zero" << trajectory_row(0.01).substr(4) << "\n";
  const std::string msg = error_of(run_dir(), out(), small());
  EXPECT_NE(msg.find("trajectory.csv:3"), std::string::npos) << msg;
  EXPECT_THROW(render_run(run_dir(), out(), small()), BadRunRecord);
  std::ofstream(dir_ / "trajectory.csv") << "t,x,y\n0,0,0\n";
  EXPECT_NE(error_of(run_dir(), out(), small()).find("no column \"phi\""), std::string::npos);
}

TEST_F(RunVideo, AFailedRenderRemovesAnOlderVideoAndSaysSo) {
  std::ofstream(out(), std::ios::binary) << std::string("\0\0\0\x18" "ftypisom", 12) << "an earlier run's video";
  fs::remove(dir_ / "trajectory.csv");
  const std::string msg = error_of(run_dir(), out(), small());
  EXPECT_NE(msg.find("trajectory.csv"), std::string::npos) << msg;
  EXPECT_NE(msg.find("the older " + out() + " was removed"), std::string::npos) << msg;
  EXPECT_FALSE(fs::exists(out()));
}

// An output file that exists and is not an MP4 is refused, not deleted: `render --out` naming
// a record of the run removed it (found in review).
TEST_F(RunVideo, AnOutputThatIsNotAVideoIsRefusedAndKept) {
  const fs::path target = dir_ / "trajectory.csv";
  const std::string before = omnitwin::testing::read_bytes(target);
  try {
    render_run(run_dir(), target.string(), small());
    ADD_FAILURE() << "no error for an output that is a record of the run";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("is not an MP4 video"), std::string::npos) << e.what();
  }
  EXPECT_EQ(omnitwin::testing::read_bytes(target), before);
  EXPECT_EQ(video_file_problem((dir_ / "absent.mp4").string()), "");
}

// The last frame is the run's last instant, also when its length is not a whole number of
// frames: at 1 fps a 3.5 s run ended on the state at 3 s (found in review).
TEST_F(RunVideo, TheLastFrameIsTheRunsLastInstant) {
  VideoOptions o = small();
  o.fps = 0.75;
  const VideoResult v = render_run(run_dir(), out(), o);
  EXPECT_EQ(v.frames, 3);  // t = 0 and 1.33 s, then the run's end at 2 s
}

// A 12 KiB tmpfs holds the run's MP4 header and a few frames, not 21.
TEST_F(RunVideo, AFullDiskLeavesNothingUnderTheFinalNameAndNamesTheFile) {
  omnitwin::testing::SmallTmpfs disk("12k");
  if (!disk.mounted()) GTEST_SKIP() << disk.skip_reason();
  const std::string file = (disk / "video.mp4").string();
  VideoOptions o = small();
  o.width = 320;
  o.height = 240;
  const std::string msg = error_of(run_dir(), file, o);
  ASSERT_NE(msg, "") << "no error on a full disk";
  EXPECT_NE(msg.find(file), std::string::npos) << msg;
  EXPECT_FALSE(fs::exists(file));
  EXPECT_FALSE(fs::exists(disk / ".video.mp4.part"));
}

TEST_F(RunVideo, UnwritableOutputAndBadOptionsAreClearErrors) {
  const std::string file = (dir_ / "missing-dir" / "video.mp4").string();
  EXPECT_NE(error_of(run_dir(), file, small()).find(file), std::string::npos);
  VideoOptions odd = small();
  odd.width = 161;
  EXPECT_THROW(render_run(run_dir(), out(), odd), std::invalid_argument);
  VideoOptions cam = small();
  cam.camera = "nosuch";
  EXPECT_NE(error_of(run_dir(), out(), cam).find("nosuch"), std::string::npos);
}

}  // namespace
}  // namespace omnitwin::media
