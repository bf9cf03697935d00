// Tests media/video_encoder: synthetic RGB frames become an H.264 yuv420p MP4 that ffprobe
// reads with the expected frame count and duration, the index at the front (faststart),
// colours in the right channel order; unwritable paths are clear errors; the file is
// written as .NAME.part and appears under its name only on close(); a full disk (a small
// tmpfs, or /dev/full behind the .part name) leaves nothing under the final name and an
// error naming it; a stale file is removed at open; an encoder destroyed without close()
// leaves nothing.
#include "media/video_encoder.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <vector>

#include "tests/bus_emulators/small_tmpfs.hpp"
#include "tests/media/media_probe.hpp"
#include "tests/support/temp_dir.hpp"

namespace omnitwin::media {
namespace {

using omnitwin::media::testing::decode_frame_rgb;
using omnitwin::media::testing::probe;
using omnitwin::testing::TempDir;

// A w x h RGB frame: a solid colour with a white square moving with k (so frames differ).
std::vector<unsigned char> synthetic_frame(int w, int h, int k, unsigned char r, unsigned char g, unsigned char b) {
  std::vector<unsigned char> f(static_cast<size_t>(w) * h * 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      unsigned char* p = &f[(static_cast<size_t>(y) * w + x) * 3];
      const bool square = x >= (2 * k) % w && x < (2 * k) % w + 16 && y < 16;
      p[0] = square ? 255 : r;
      p[1] = square ? 255 : g;
      p[2] = square ? 255 : b;
    }
  return f;
}

EncoderOptions small(double fps = 10) { return EncoderOptions{.width = 160, .height = 120, .fps = fps}; }

TEST(VideoEncoder, WritesH264Yuv420pWithTheFramesAndDurationGiven) {
  TempDir dir("omnitwin-video");
  const std::string file = (dir / "out.mp4").string();
  VideoEncoder enc(file, small(10));
  for (int k = 0; k < 25; ++k) enc.add_frame(synthetic_frame(160, 120, k, 30, 60, 90).data());
  enc.close();
  EXPECT_EQ(enc.frames(), 25);
  EXPECT_DOUBLE_EQ(enc.duration_s(), 2.5);
  const auto s = probe(file);
  ASSERT_EQ(s.status, 0);
  EXPECT_EQ(s.codec, "h264");
  EXPECT_EQ(s.pix_fmt, "yuv420p");
  EXPECT_EQ(s.width, 160);
  EXPECT_EQ(s.height, 120);
  EXPECT_EQ(s.frames, 25);
  EXPECT_NEAR(s.duration_s, 2.5, 0.01);
}

TEST(VideoEncoder, PutsTheIndexBeforeTheMediaDataForBrowsers) {
  TempDir dir("omnitwin-video");
  const auto file = dir / "fast.mp4";
  {
    VideoEncoder enc(file.string(), small());
    for (int k = 0; k < 5; ++k) enc.add_frame(synthetic_frame(160, 120, k, 0, 0, 0).data());
    enc.close();
  }
  const std::string bytes = omnitwin::testing::read_bytes(file);
  const auto moov = bytes.find("moov"), mdat = bytes.find("mdat");
  ASSERT_NE(moov, std::string::npos);
  ASSERT_NE(mdat, std::string::npos);
  EXPECT_LT(moov, mdat);
}

TEST(VideoEncoder, KeepsRedGreenBlueInTheirChannels) {
  TempDir dir("omnitwin-video");
  const std::string file = (dir / "rgb.mp4").string();
  {
    VideoEncoder enc(file, small());
    for (int k = 0; k < 3; ++k) enc.add_frame(synthetic_frame(160, 120, 0, 200, 40, 20).data());
    enc.close();
  }
  const std::string rgb = decode_frame_rgb(file, 1);
  ASSERT_EQ(rgb.size(), 160u * 120u * 3u);
  const size_t centre = (60 * 160 + 80) * 3;  // outside the white square
  EXPECT_NEAR(static_cast<unsigned char>(rgb[centre + 0]), 200, 12);
  EXPECT_NEAR(static_cast<unsigned char>(rgb[centre + 1]), 40, 12);
  EXPECT_NEAR(static_cast<unsigned char>(rgb[centre + 2]), 20, 12);
}

TEST(VideoEncoder, DestroyedWithoutCloseLeavesNothingUnderTheFinalName) {
  TempDir dir("omnitwin-video");
  const std::string file = (dir / "unclosed.mp4").string();
  {
    VideoEncoder enc(file, small());
    for (int k = 0; k < 7; ++k) enc.add_frame(synthetic_frame(160, 120, k, 10, 10, 10).data());
  }  // an exception unwinding: the recording is abandoned
  EXPECT_FALSE(std::filesystem::exists(file));
  EXPECT_FALSE(std::filesystem::exists(dir / ".unclosed.mp4.part"));
}

TEST(VideoEncoder, WritesAPartFileAndRenamesItOnlyOnClose) {
  TempDir dir("omnitwin-video");
  const std::string file = (dir / "video.mp4").string();
  VideoEncoder enc(file, small());
  EXPECT_EQ(enc.part_path(), (dir / ".video.mp4.part").string());
  for (int k = 0; k < 5; ++k) enc.add_frame(synthetic_frame(160, 120, k, 10, 10, 10).data());
  EXPECT_TRUE(std::filesystem::exists(enc.part_path()));
  EXPECT_FALSE(std::filesystem::exists(file));
  enc.close();
  EXPECT_FALSE(std::filesystem::exists(enc.part_path()));
  const auto s = probe(file);
  ASSERT_EQ(s.status, 0);
  EXPECT_EQ(s.frames, 5);
}

TEST(VideoEncoder, AStaleFileIsRemovedWhenANewOneOpens) {
  TempDir dir("omnitwin-video");
  const std::string file = (dir / "video.mp4").string();
  std::ofstream(file) << "an older video";
  VideoEncoder enc(file, small());
  EXPECT_TRUE(enc.replaced_old());
  EXPECT_FALSE(std::filesystem::exists(file)) << "the old video must not pass for the new one";
  enc.add_frame(synthetic_frame(160, 120, 0, 10, 10, 10).data());
  enc.close();
  EXPECT_EQ(probe(file).frames, 1);
}

TEST(VideoEncoder, UnwritableDirectoryIsAClearErrorNamingTheFile) {
  TempDir dir("omnitwin-video");
  const std::string file = (dir / "no-such-dir" / "out.mp4").string();
  try {
    VideoEncoder enc(file, small());
    FAIL() << "no error for " << file;
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("cannot open the file for writing"), std::string::npos) << e.what();
  }
}

// Noise does not compress: about 20 KB per 160x120 frame, so a 64 KiB disk fills in a few.
std::vector<unsigned char> noise_frame(std::mt19937& rng) {
  std::vector<unsigned char> f(160 * 120 * 3);
  for (auto& b : f) b = static_cast<unsigned char>(rng());
  return f;
}

// Encodes `frames` noise frames into file and closes; the runtime_error's text ("" if none).
std::string encode_noise(const std::string& file, int frames) {
  std::mt19937 rng(7);
  try {
    VideoEncoder enc(file, small());
    for (int k = 0; k < frames; ++k) enc.add_frame(noise_frame(rng).data());
    enc.close();
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

TEST(VideoEncoder, FullDiskLeavesNothingUnderTheFinalNameAndNamesTheFile) {
  omnitwin::testing::SmallTmpfs disk("64k");
  if (!disk.mounted()) GTEST_SKIP() << disk.skip_reason();
  const std::string file = (disk / "video.mp4").string();
  std::ofstream(file) << "an older video";
  const std::string msg = encode_noise(file, 60);
  ASSERT_NE(msg, "") << "no error on a full disk";
  EXPECT_NE(msg.find(file), std::string::npos) << msg;
  EXPECT_NE(msg.find("the older " + file + " was removed"), std::string::npos) << msg;
  // It names its temporary file as gone, not as where the video was "written" (found in review).
  EXPECT_NE(msg.find("(through the temporary " + (disk / ".video.mp4.part").string() + ", not kept)"), std::string::npos)
      << msg;
  EXPECT_FALSE(std::filesystem::exists(file));
  EXPECT_FALSE(std::filesystem::exists(disk / ".video.mp4.part"));
}

// Without root: /dev/full (every write fails with ENOSPC) behind the .part name.
TEST(VideoEncoder, DevFullBehindThePartNameIsAnErrorAndNoFile) {
  if (!std::filesystem::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  TempDir dir("omnitwin-video");
  const std::string file = (dir / "video.mp4").string();
  std::filesystem::create_symlink("/dev/full", dir / ".video.mp4.part");
  const std::string msg = encode_noise(file, 30);
  ASSERT_NE(msg, "") << "no error writing to /dev/full";
  EXPECT_NE(msg.find(file), std::string::npos) << msg;
  EXPECT_FALSE(std::filesystem::exists(file));
  EXPECT_FALSE(std::filesystem::is_symlink(dir / ".video.mp4.part"));
}

TEST(VideoEncoder, RejectsOddSizesAndBadFrameRates) {
  TempDir dir("omnitwin-video");
  const std::string file = (dir / "bad.mp4").string();
  EXPECT_THROW(VideoEncoder(file, EncoderOptions{.width = 161, .height = 120}), std::invalid_argument);
  EXPECT_THROW(VideoEncoder(file, EncoderOptions{.width = 160, .height = 0}), std::invalid_argument);
  EXPECT_THROW(VideoEncoder(file, EncoderOptions{.width = 160, .height = 120, .fps = 0}), std::invalid_argument);
}

TEST(VideoEncoder, AddingAfterCloseIsALogicError) {
  TempDir dir("omnitwin-video");
  VideoEncoder enc((dir / "closed.mp4").string(), small());
  enc.add_frame(synthetic_frame(160, 120, 0, 0, 0, 0).data());
  enc.close();
  enc.close();  // idempotent
  EXPECT_THROW(enc.add_frame(synthetic_frame(160, 120, 0, 0, 0, 0).data()), std::logic_error);
}

}  // namespace
}  // namespace omnitwin::media
