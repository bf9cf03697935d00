// media layer — RGB frames in, H.264 MP4 out (libavformat/libavcodec/libswscale, libx264).
//
// The encoder is the only place that knows libav: callers hand it top-down RGB24 frames of
// the size it was opened with and get a file that browsers play (H.264 High, yuv420p,
// `moov` atom at the front: movflags +faststart). Frame k is shown at k / fps seconds.
// The file is written as DIR/.NAME.part (muxer "mp4" named explicitly) and renamed to
// DIR/NAME by close() only after the trailer is written and every write succeeded, so the
// final name never holds a cut or corrupt file: a process killed while finishing leaves only
// the .part file. A stale DIR/NAME from before is removed when the encoder opens, so an old
// video never passes for the new one. On any failure the .part file is removed and the
// std::runtime_error names the file, libav's reason (unwritable directory, disk full, codec
// missing) and, when it happened, that the older file was removed. An encoder destroyed
// without close() (an exception unwinding) removes its .part file: an abandoned recording
// is not a result. A stop request is the caller's close() after the frames so far (DESIGN
// §11). libav headers stay in the .cpp (pimpl). Opening an encoder lowers libav's
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
  // Removes a stale `path`, opens its .part file and writes the MP4 header. Throws
  // std::invalid_argument for odd/non-positive sizes or fps <= 0, std::runtime_error naming
  // the file for any libav failure. Not real-time safe.
  VideoEncoder(const std::string& path, const EncoderOptions& options);
  // Without close(): removes the .part file (nothing appears under `path`). Never throws.
  ~VideoEncoder();
  VideoEncoder(VideoEncoder&&) noexcept;
  VideoEncoder& operator=(VideoEncoder&&) noexcept;
  VideoEncoder(const VideoEncoder&) = delete;
  VideoEncoder& operator=(const VideoEncoder&) = delete;

  // Encodes one frame: width*height*3 bytes, RGB24, rows top to bottom. Throws
  // std::runtime_error naming the file on libav failures (e.g. disk full; the .part file is
  // then removed and close() does nothing), std::logic_error after close() or a failure.
  // Not real-time safe (encodes, may write).
  void add_frame(const unsigned char* rgb);

  // Flushes the encoder, writes the trailer (moving the index to the front), closes the
  // .part file and renames it to path(). Not interruptible: it looks at no stop flag.
  // Idempotent. On failure removes the .part file and throws std::runtime_error naming the
  // file; nothing is then under path().
  void close();

  int frames() const;             // frames added so far
  double duration_s() const;      // frames() / fps [s]
  const std::string& path() const;       // the final name
  const std::string& part_path() const;  // where the file is until close() renames it
  bool replaced_old() const;             // a file under path() was removed at open

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace omnitwin::media
