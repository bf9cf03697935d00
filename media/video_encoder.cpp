// media layer — VideoEncoder on libav (see video_encoder.hpp). Each libav object has its own
// owning handle; Impl holds them in the order they are torn down.
#include "media/video_encoder.hpp"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/error.h>
#include <libavutil/imgutils.h>
#include <libavutil/opt.h>
#include <libswscale/swscale.h>
}

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string>

namespace omnitwin::media {
namespace {

// Owning handles of the libav objects.
struct FormatDeleter {
  void operator()(AVFormatContext* f) const {
    if (f->pb && !(f->oformat->flags & AVFMT_NOFILE)) avio_closep(&f->pb);
    avformat_free_context(f);
  }
};
struct CodecDeleter {
  void operator()(AVCodecContext* c) const { avcodec_free_context(&c); }
};
struct FrameDeleter {
  void operator()(AVFrame* f) const { av_frame_free(&f); }
};
struct PacketDeleter {
  void operator()(AVPacket* p) const { av_packet_free(&p); }
};
struct SwsDeleter {
  void operator()(SwsContext* s) const { sws_freeContext(s); }
};
using FormatPtr = std::unique_ptr<AVFormatContext, FormatDeleter>;
using CodecPtr = std::unique_ptr<AVCodecContext, CodecDeleter>;
using FramePtr = std::unique_ptr<AVFrame, FrameDeleter>;
using PacketPtr = std::unique_ptr<AVPacket, PacketDeleter>;
using SwsPtr = std::unique_ptr<SwsContext, SwsDeleter>;

std::string av_error_text(int err) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {};
  av_strerror(err, buf, sizeof buf);
  return buf;
}

void validate(const EncoderOptions& o) {
  if (o.width < 2 || o.height < 2 || o.width % 2 || o.height % 2)
    throw std::invalid_argument("video size must be even and >= 2 (yuv420p), got " +
                                std::to_string(o.width) + "x" + std::to_string(o.height));
  if (!(o.fps > 0) || o.fps > 1000)
    throw std::invalid_argument("video fps must be in (0, 1000], got " + std::to_string(o.fps));
}

// libav logs every opened encoder and the faststart pass at "info"; the project's logs are
// quiet unless something is wrong. The level is libav's own process-wide setting: it is
// only ever lowered to warnings here, never raised.
void quiet_libav_logs() {
  if (av_log_get_level() > AV_LOG_WARNING) av_log_set_level(AV_LOG_WARNING);
}

// "DIR/.NAME.part" beside DIR/NAME (one file system, so the rename is atomic).
std::string part_path_of(const std::string& path) {
  const std::filesystem::path p(path);
  return (p.parent_path() / ("." + p.filename().string() + ".part")).string();
}

// Removes a regular file or link at path; true if there was one.
bool remove_stale(const std::string& path) {
  std::error_code ec;
  const auto st = std::filesystem::symlink_status(path, ec);
  if (ec || std::filesystem::is_directory(st)) return false;
  return std::filesystem::remove(path, ec);
}

}  // namespace

struct VideoEncoder::Impl {
  std::string path;       // the final name
  std::string part;       // DIR/.NAME.part, renamed to path by close()
  bool removed_old = false;
  EncoderOptions opt;
  FormatPtr fmt;  // destroyed last (members go in reverse order)
  CodecPtr codec;
  FramePtr frame;
  PacketPtr packet;
  SwsPtr sws;
  AVStream* stream = nullptr;  // owned by fmt
  int frames = 0;
  bool open = false;

  // Throws "<path>: <what>: <libav reason>" when err < 0; returns err otherwise.
  int check(int err, const char* what) const {
    if (err < 0) fail(std::string(what) + ": " + av_error_text(err));
    return err;
  }
  [[noreturn]] void fail(const std::string& why) const {
    // The temporary file is removed when the encoder goes (or was never made): not kept.
    throw std::runtime_error("video " + path + ": " + why + " (through the temporary " + part + ", not kept)" +
                             (removed_old ? "; the older " + path + " was removed" : ""));
  }

  void open_codec();
  void open_file();
  void set_up_frames();
  void drain(bool flushing);
  void finish();
  void discard() noexcept;
};

void VideoEncoder::Impl::open_codec() {
  const AVCodec* c = avcodec_find_encoder_by_name("libx264");
  if (!c) throw std::runtime_error("video " + path + ": libavcodec has no libx264 encoder");
  codec.reset(avcodec_alloc_context3(c));
  if (!codec) throw std::runtime_error("video " + path + ": out of memory (codec context)");
  const AVRational rate = av_d2q(opt.fps, 100000);
  codec->width = opt.width;
  codec->height = opt.height;
  codec->pix_fmt = AV_PIX_FMT_YUV420P;
  codec->framerate = rate;
  codec->time_base = av_inv_q(rate);
  codec->gop_size = std::max(1, static_cast<int>(opt.fps * 2));  // a keyframe every ~2 s
  if (fmt->oformat->flags & AVFMT_GLOBALHEADER) codec->flags |= AV_CODEC_FLAG_GLOBAL_HEADER;
  av_opt_set(codec->priv_data, "preset", opt.preset.c_str(), 0);
  av_opt_set(codec->priv_data, "crf", std::to_string(opt.crf).c_str(), 0);
  av_opt_set(codec->priv_data, "x264-params", "log=0", 0);  // x264 errors only, no stats
  check(avcodec_open2(codec.get(), c, nullptr), "cannot open the H.264 encoder");
}

void VideoEncoder::Impl::open_file() {
  AVFormatContext* raw = nullptr;
  check(avformat_alloc_output_context2(&raw, nullptr, "mp4", part.c_str()), "cannot set up MP4 output");
  fmt.reset(raw);
  open_codec();
  stream = avformat_new_stream(fmt.get(), nullptr);
  if (!stream) throw std::runtime_error("video " + path + ": out of memory (stream)");
  stream->time_base = codec->time_base;
  stream->avg_frame_rate = codec->framerate;
  check(avcodec_parameters_from_context(stream->codecpar, codec.get()), "cannot copy codec parameters");
  check(avio_open(&fmt->pb, part.c_str(), AVIO_FLAG_WRITE), "cannot open the file for writing");
  AVDictionary* mux = nullptr;
  av_dict_set(&mux, "movflags", "+faststart", 0);
  const int err = avformat_write_header(fmt.get(), &mux);
  av_dict_free(&mux);
  check(err, "cannot write the MP4 header");
  open = true;
}

// Moves every packet the encoder has ready into the file.
void VideoEncoder::Impl::drain(bool flushing) {
  for (;;) {
    const int err = avcodec_receive_packet(codec.get(), packet.get());
    if (err == AVERROR(EAGAIN) || (flushing && err == AVERROR_EOF)) return;
    check(err, "encoding failed");
    av_packet_rescale_ts(packet.get(), codec->time_base, stream->time_base);
    packet->stream_index = stream->index;
    check(av_interleaved_write_frame(fmt.get(), packet.get()), "cannot write to the file (disk full?)");
  }
}

// The frame buffer and the RGB → YUV converter, once the file is open.
void VideoEncoder::Impl::set_up_frames() {
  frame.reset(av_frame_alloc());
  packet.reset(av_packet_alloc());
  if (!frame || !packet) fail("out of memory (frame)");
  frame->format = AV_PIX_FMT_YUV420P;
  frame->width = opt.width;
  frame->height = opt.height;
  check(av_frame_get_buffer(frame.get(), 0), "cannot allocate a frame");
  sws.reset(sws_getContext(opt.width, opt.height, AV_PIX_FMT_RGB24, opt.width, opt.height, AV_PIX_FMT_YUV420P,
                           SWS_BILINEAR, nullptr, nullptr, nullptr));
  if (!sws) fail("cannot set up RGB to YUV conversion");
}

// Flushes the codec, writes the trailer (the faststart pass rewrites the .part file), closes
// it, and only when every step succeeded renames it to the final name.
void VideoEncoder::Impl::finish() {
  check(avcodec_send_frame(codec.get(), nullptr), "encoding failed");
  drain(true);
  check(av_write_trailer(fmt.get()), "cannot finish the MP4 file (disk full?)");
  check(fmt->pb->error, "cannot write to the file (disk full?)");
  check(avio_closep(&fmt->pb), "cannot close the file (disk full?)");
  if (std::rename(part.c_str(), path.c_str()) != 0)
    fail(std::string("cannot rename to the final name: ") + std::strerror(errno));
}

// Closes the file without finishing it and removes it: nothing appears under the final name.
void VideoEncoder::Impl::discard() noexcept {
  if (fmt && fmt->pb) avio_closep(&fmt->pb);
  std::error_code ec;
  std::filesystem::remove(part, ec);
}

VideoEncoder::VideoEncoder(const std::string& path, const EncoderOptions& options)
    : impl_(std::make_unique<Impl>()) {
  validate(options);
  quiet_libav_logs();
  Impl& m = *impl_;
  m.path = path;
  m.part = part_path_of(path);
  m.opt = options;
  m.removed_old = remove_stale(path);  // an old video must not pass for this one
  try {
    m.open_file();
    m.set_up_frames();
  } catch (...) {
    m.open = false;
    m.discard();
    throw;
  }
}

VideoEncoder::~VideoEncoder() {
  if (impl_ && impl_->open) impl_->discard();
}

VideoEncoder::VideoEncoder(VideoEncoder&&) noexcept = default;
VideoEncoder& VideoEncoder::operator=(VideoEncoder&&) noexcept = default;

void VideoEncoder::add_frame(const unsigned char* rgb) {
  Impl& m = *impl_;
  if (!m.open) throw std::logic_error("video " + m.path + ": add_frame after close or a failure");
  try {
    m.check(av_frame_make_writable(m.frame.get()), "cannot write the frame buffer");
    const uint8_t* src[1] = {rgb};
    const int stride[1] = {3 * m.opt.width};
    sws_scale(m.sws.get(), src, stride, 0, m.opt.height, m.frame->data, m.frame->linesize);
    m.frame->pts = m.frames;
    m.check(avcodec_send_frame(m.codec.get(), m.frame.get()), "encoding failed");
    ++m.frames;
    m.drain(false);
  } catch (...) {
    m.open = false;  // a failed write is never finished into a file: close() has nothing to do
    m.discard();
    throw;
  }
}

void VideoEncoder::close() {
  Impl& m = *impl_;
  if (!m.open) return;
  m.open = false;  // a failure below leaves nothing to retry
  try {
    m.finish();
  } catch (...) {
    m.discard();
    throw;
  }
}

int VideoEncoder::frames() const { return impl_->frames; }
double VideoEncoder::duration_s() const { return impl_->frames / impl_->opt.fps; }
const std::string& VideoEncoder::path() const { return impl_->path; }
const std::string& VideoEncoder::part_path() const { return impl_->part; }
bool VideoEncoder::replaced_old() const { return impl_->removed_old; }

}  // namespace omnitwin::media
