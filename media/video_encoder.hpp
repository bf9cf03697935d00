// media layer — RGB frames in, H.264 MP4 out (libavformat/libavcodec/libswscale, libx264).
//
// The encoder is the only place that knows libav: callers hand it top-down RGB24 frames of
// the size it was opened with and get a file that browsers play (H.264 High, yuv420p,
// `moov` atom at the front: movflags +faststart). Frame k is shown at k / fps seconds.
// The file is finished by close() (flush the codec, write the trailer, close the file); the
// destructor does the same if close() was not called, so a recording interrupted by an
// exception or a stop request is still a playable file (DESIGN §11). Every libav failure is
// a std::runtime_error naming the file and libav's reason (unwritable directory, disk full,
// codec missing). libav headers stay in the .cpp (pimpl). Opening an encoder lowers libav's
// process-wide log level to warnings (its "info" lines would otherwise go to stderr).
#pragma once

#include <memory>
#include <string>

namespace omnitwin::media {

struct EncoderOptions {
  int width = 640;                  // [pixels], even, >= 2
  int height = 480;                 // [pixels], even, >= 2
  double fps = 30;                  // frame rate [1/s], > 0
  int crf = 23;                     // x264 constant rate factor (0 lossless … 51 worst)
  std::string preset = "veryfast";  // x264 speed/size trade-off
};

class VideoEncoder {
 public:
  // Opens `path` for writing (created or truncated) and writes the MP4 header. Throws
  // std::invalid_argument for odd/non-positive sizes or fps <= 0, std::runtime_error naming
  // the file for any libav failure. Not real-time safe.
  VideoEncoder(const std::string& path, const EncoderOptions& options);
  // Finalises the file like close() if that was not called; errors are swallowed (logged).
  ~VideoEncoder();
  VideoEncoder(VideoEncoder&&) noexcept;
  VideoEncoder& operator=(VideoEncoder&&) noexcept;
  VideoEncoder(const VideoEncoder&) = delete;
  VideoEncoder& operator=(const VideoEncoder&) = delete;

  // Encodes one frame: width*height*3 bytes, RGB24, rows top to bottom. Throws
  // std::runtime_error naming the file on libav failures (e.g. disk full), std::logic_error
  // after close(). Not real-time safe (encodes, may write).
  void add_frame(const unsigned char* rgb);

  // Flushes the encoder, writes the trailer (moving the index to the front) and closes the
  // file. Idempotent. Throws std::runtime_error naming the file on failure.
  void close();

  int frames() const;             // frames added so far
  double duration_s() const;      // frames() / fps [s]
  const std::string& path() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace omnitwin::media
