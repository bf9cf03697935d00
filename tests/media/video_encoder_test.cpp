// Tests media/video_encoder: synthetic RGB frames become an H.264 yuv420p MP4 that ffprobe
// reads with the expected frame count and duration, the index at the front (faststart),
// colours in the right channel order; unwritable paths and a full disk are clear errors;
// an encoder destroyed without close() still leaves a playable file.
#include "media/video_encoder.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <vector>

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
  }
  const std::string rgb = decode_frame_rgb(file, 1);
  ASSERT_EQ(rgb.size(), 160u * 120u * 3u);
  const size_t centre = (60 * 160 + 80) * 3;  // outside the white square
  EXPECT_NEAR(static_cast<unsigned char>(rgb[centre + 0]), 200, 12);
  EXPECT_NEAR(static_cast<unsigned char>(rgb[centre + 1]), 40, 12);
  EXPECT_NEAR(static_cast<unsigned char>(rgb[centre + 2]), 20, 12);
}

TEST(VideoEncoder, DestroyedWithoutCloseStillLeavesAPlayableFile) {
  TempDir dir("omnitwin-video");
  const std::string file = (dir / "unclosed.mp4").string();
  {
    VideoEncoder enc(file, small());
    for (int k = 0; k < 7; ++k) enc.add_frame(synthetic_frame(160, 120, k, 10, 10, 10).data());
  }
  const auto s = probe(file);
  ASSERT_EQ(s.status, 0);
  EXPECT_EQ(s.codec, "h264");
  EXPECT_EQ(s.frames, 7);
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

// /dev/full accepts open() and fails every write with ENOSPC: a disk that is full.
TEST(VideoEncoder, FullDiskIsAClearErrorNamingTheFile) {
  if (!std::filesystem::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  try {
    VideoEncoder enc("/dev/full", small());
    for (int k = 0; k < 30; ++k) enc.add_frame(synthetic_frame(160, 120, k, 1, 2, 3).data());
    enc.close();
    FAIL() << "no error writing to /dev/full";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/dev/full"), std::string::npos) << e.what();
  }
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
