// bus_emulators/can — python-can `udp_multicast` msgpack codec; see can_msgpack.hpp.
//
// Decoding uses msgpack-cxx's SAX-style parser (msgpack::parse with a visitor): no object
// tree, no zone, and the visitor stops the parser at the first thing it does not accept, so
// a hostile size field (a map of 2^32 entries, a 4 GiB bin) costs nothing.
#include "bus_emulators/can/can_msgpack.hpp"

#include <msgpack.hpp>

#include <algorithm>
#include <cstring>
#include <stdexcept>
#include <string_view>

namespace omnitwin::can::msgpack_wire {

const char* to_string(DecodeStatus s) {
  switch (s) {
    case DecodeStatus::ok: return "ok";
    case DecodeStatus::malformed: return "malformed";
    case DecodeStatus::unknown_key: return "unknown key";
    case DecodeStatus::bad_type: return "bad value type";
    case DecodeStatus::bad_id: return "identifier out of range";
    case DecodeStatus::wrong_dlc: return "wrong DLC";
    case DecodeStatus::invalid_flags: return "invalid flag combination";
    case DecodeStatus::fd_unsupported: return "CAN FD frame (unsupported)";
  }
  return "?";
}

namespace {

// ---- encoding -------------------------------------------------------------------------

// A msgpack-cxx output stream over a caller's fixed buffer; remembers overflow.
class SpanWriter {
 public:
  explicit SpanWriter(std::span<std::uint8_t> out) : out_(out) {}
  void write(const char* p, std::size_t n) {
    if (overflow_ || n > out_.size() - used_) {
      overflow_ = true;
      return;
    }
    std::memcpy(out_.data() + used_, p, n);
    used_ += n;
  }
  std::size_t used() const { return overflow_ ? 0 : used_; }

 private:
  std::span<std::uint8_t> out_;
  std::size_t used_ = 0;
  bool overflow_ = false;
};

void pack_key(msgpack::packer<SpanWriter>& pk, std::string_view k) {
  pk.pack_str(static_cast<std::uint32_t>(k.size()));
  pk.pack_str_body(k.data(), static_cast<std::uint32_t>(k.size()));
}

// Always float64 (0xcb), as Python's msgpack packs a float. msgpack-cxx's pack_double()
// writes integral values as integers, which would break byte-identity with python-can.
void pack_float64(SpanWriter& w, double v) {
  std::uint64_t bits = 0;
  std::memcpy(&bits, &v, sizeof bits);
  char b[9];
  b[0] = static_cast<char>(0xcb);
  for (int i = 0; i < 8; ++i) b[1 + i] = static_cast<char>(bits >> (56 - 8 * i));
  w.write(b, sizeof b);
}

void pack_bool(msgpack::packer<SpanWriter>& pk, bool b) {
  if (b) pk.pack_true();
  else pk.pack_false();
}

// ---- decoding -------------------------------------------------------------------------

enum class Key : std::uint8_t {
  none, timestamp, arbitration_id, is_extended_id, is_remote_frame, is_error_frame, channel,
  dlc, data, is_fd, bitrate_switch, error_state_indicator, count
};

constexpr std::string_view kKeyNames[] = {
    "",      "timestamp", "arbitration_id", "is_extended_id", "is_remote_frame", "is_error_frame",
    "channel", "dlc",     "data",           "is_fd",          "bitrate_switch",
    "error_state_indicator"};

Key lookup_key(std::string_view s) {
  for (int k = 1; k < static_cast<int>(Key::count); ++k)
    if (kKeyNames[k] == s) return static_cast<Key>(k);
  return Key::none;
}

constexpr std::uint32_t kMaxMapEntries = 32;   // python-can sends 11
constexpr std::uint32_t kMaxFdBytes = 64;

// Fields as python-can's Message() would see them, with its defaults.
struct Fields {
  double timestamp = 0.0;
  std::uint64_t arbitration_id = 0;
  bool is_extended_id = true;  // python-can's Message default
  bool is_remote_frame = false;
  bool is_error_frame = false;
  bool is_fd = false;
  bool bitrate_switch = false;
  bool error_state_indicator = false;
  bool has_dlc = false;
  std::uint64_t dlc = 0;
  std::uint32_t data_len = 0;  // may exceed 8 (FD, or a bad frame); only 8 bytes are kept
  std::array<std::uint8_t, 8> data{};
  std::uint32_t seen = 0;      // bit per Key, for duplicates
};

class Visitor {
 public:
  explicit Visitor(Fields& f) : f_(f) {}
  DecodeStatus status() const { return status_; }

  bool visit_nil() {
    if (!value_ok()) return false;
    switch (key_) {
      case Key::timestamp: f_.timestamp = 0.0; return true;  // python-can replaces it anyway
      case Key::channel: return true;
      case Key::dlc: f_.has_dlc = false; return true;        // python-can: dlc = len(data)
      case Key::data: f_.data_len = 0; return true;
      default: return fail(DecodeStatus::bad_type);
    }
  }
  bool visit_boolean(bool v) {
    if (!value_ok()) return false;
    switch (key_) {
      case Key::is_extended_id: f_.is_extended_id = v; return true;
      case Key::is_remote_frame: f_.is_remote_frame = v; return true;
      case Key::is_error_frame: f_.is_error_frame = v; return true;
      case Key::is_fd: f_.is_fd = v; return true;
      case Key::bitrate_switch: f_.bitrate_switch = v; return true;
      case Key::error_state_indicator: f_.error_state_indicator = v; return true;
      case Key::channel: return true;
      default: return fail(DecodeStatus::bad_type);
    }
  }
  bool visit_positive_integer(std::uint64_t v) {
    if (in_data_array_) return data_byte(v);
    if (!value_ok()) return false;
    switch (key_) {
      case Key::timestamp: f_.timestamp = static_cast<double>(v); return true;
      case Key::arbitration_id: f_.arbitration_id = v; return true;
      case Key::dlc: f_.dlc = v; f_.has_dlc = true; return true;
      case Key::channel: return true;
      default: return fail(DecodeStatus::bad_type);
    }
  }
  bool visit_negative_integer(std::int64_t v) {
    if (in_data_array_) return fail(DecodeStatus::bad_type);
    if (!value_ok()) return false;
    switch (key_) {
      case Key::timestamp: f_.timestamp = static_cast<double>(v); return true;
      case Key::arbitration_id: return fail(DecodeStatus::bad_id);
      case Key::dlc: return fail(DecodeStatus::wrong_dlc);
      case Key::channel: return true;
      default: return fail(DecodeStatus::bad_type);
    }
  }
  bool visit_float32(float v) { return visit_float64(static_cast<double>(v)); }
  bool visit_float64(double v) {
    if (in_data_array_) return fail(DecodeStatus::bad_type);
    if (!value_ok()) return false;
    if (key_ == Key::timestamp) { f_.timestamp = v; return true; }
    if (key_ == Key::channel) return true;
    return fail(DecodeStatus::bad_type);
  }
  bool visit_str(const char* p, std::uint32_t n) {
    if (in_data_array_) return fail(DecodeStatus::bad_type);
    if (depth_ == 0) return fail(DecodeStatus::malformed);
    if (in_key_) {
      const Key k = lookup_key(std::string_view(p, n));
      if (k == Key::none) return fail(DecodeStatus::unknown_key);
      const std::uint32_t bit = 1u << static_cast<unsigned>(k);
      if (f_.seen & bit) return fail(DecodeStatus::unknown_key);  // duplicate key
      f_.seen |= bit;
      key_ = k;
      have_key_ = true;
      return true;
    }
    if (key_ == Key::channel) return true;
    return fail(DecodeStatus::bad_type);
  }
  bool visit_bin(const char* p, std::uint32_t n) {
    if (in_data_array_) return fail(DecodeStatus::bad_type);
    if (!value_ok()) return false;
    if (key_ == Key::channel) return true;
    if (key_ != Key::data) return fail(DecodeStatus::bad_type);
    if (n > kMaxFdBytes) return fail(DecodeStatus::wrong_dlc);
    f_.data_len = n;
    std::memcpy(f_.data.data(), p, std::min<std::uint32_t>(n, 8));
    return true;
  }
  bool visit_ext(const char*, std::uint32_t) {
    if (!value_ok()) return false;
    return fail(DecodeStatus::bad_type);
  }
  bool start_array(std::uint32_t n) {
    if (depth_ == 0 || in_key_ || in_data_array_) return fail(DecodeStatus::malformed);
    if (!value_ok()) return false;
    if (key_ != Key::data) return fail(DecodeStatus::bad_type);
    if (n > kMaxFdBytes) return fail(DecodeStatus::wrong_dlc);
    in_data_array_ = true;
    f_.data_len = 0;
    return true;
  }
  bool start_array_item() { return true; }
  bool end_array_item() { return true; }
  bool end_array() {
    in_data_array_ = false;
    return true;
  }
  bool start_map(std::uint32_t n) {
    if (depth_ != 0 || seen_top_) return fail(in_key_ ? DecodeStatus::unknown_key : DecodeStatus::malformed);
    if (n > kMaxMapEntries) return fail(DecodeStatus::malformed);
    seen_top_ = true;
    depth_ = 1;
    return true;
  }
  bool start_map_key() {
    in_key_ = true;
    have_key_ = false;
    return true;
  }
  bool end_map_key() {
    in_key_ = false;
    return true;
  }
  bool start_map_value() { return true; }
  bool end_map_value() {
    key_ = Key::none;
    have_key_ = false;
    return true;
  }
  bool end_map() {
    depth_ = 0;
    return true;
  }
  void parse_error(std::size_t, std::size_t) { set(DecodeStatus::malformed); }
  void insufficient_bytes(std::size_t, std::size_t) { set(DecodeStatus::malformed); }
  bool referenced() const { return false; }
  void set_referenced(bool) {}

 private:
  // A scalar is acceptable only as the value of a known key of the top-level map.
  bool value_ok() {
    if (in_data_array_) return fail(DecodeStatus::bad_type);     // only integers in `data`
    if (depth_ == 0) return fail(DecodeStatus::malformed);       // top level is not a map
    if (in_key_) return fail(DecodeStatus::unknown_key);         // non-string key
    if (!have_key_) return fail(DecodeStatus::malformed);
    return true;
  }
  bool data_byte(std::uint64_t v) {
    if (v > 255) return fail(DecodeStatus::bad_type);
    if (f_.data_len < 8) f_.data[f_.data_len] = static_cast<std::uint8_t>(v);
    ++f_.data_len;
    return true;
  }
  bool fail(DecodeStatus s) {
    set(s);
    return false;
  }
  void set(DecodeStatus s) {
    if (status_ == DecodeStatus::ok) status_ = s;
  }

  Fields& f_;
  DecodeStatus status_ = DecodeStatus::ok;
  int depth_ = 0;
  bool seen_top_ = false;
  bool in_key_ = false;
  bool have_key_ = false;
  bool in_data_array_ = false;
  Key key_ = Key::none;
};

// python-can's Message._check(), mapped onto our statuses.
DecodeStatus validate(const Fields& f) {
  if (f.is_remote_frame && f.is_error_frame) return DecodeStatus::invalid_flags;
  if (f.is_remote_frame && f.is_fd) return DecodeStatus::invalid_flags;
  const std::uint64_t max_id = f.is_extended_id ? 0x1FFFFFFFu : 0x7FFu;
  if (f.arbitration_id > max_id) return DecodeStatus::bad_id;
  const std::uint64_t dlc = f.has_dlc ? f.dlc : f.data_len;
  if (dlc > (f.is_fd ? kMaxFdBytes : 8u)) return DecodeStatus::wrong_dlc;
  if (f.is_remote_frame) {
    if (f.data_len != 0) return DecodeStatus::invalid_flags;
  } else if (dlc != f.data_len) {
    return DecodeStatus::wrong_dlc;
  }
  if (!f.is_fd && (f.bitrate_switch || f.error_state_indicator)) return DecodeStatus::invalid_flags;
  if (f.is_fd) return DecodeStatus::fd_unsupported;
  return DecodeStatus::ok;
}

}  // namespace

std::size_t encode(const Frame& f, double timestamp_s, std::span<std::uint8_t> out) {
  if (!f.valid()) return 0;
  const bool remote = f.kind == FrameKind::remote;
  const std::uint8_t n = remote ? 0 : f.dlc;  // valid(): dlc <= 8
  SpanWriter w(out);
  msgpack::packer<SpanWriter> pk(w);
  pk.pack_map(11);
  pack_key(pk, "timestamp");
  pack_float64(w, timestamp_s);
  pack_key(pk, "arbitration_id");
  pk.pack_uint32(f.id);
  pack_key(pk, "is_extended_id");
  pack_bool(pk, f.extended);
  pack_key(pk, "is_remote_frame");
  pack_bool(pk, remote);
  pack_key(pk, "is_error_frame");
  pack_bool(pk, f.kind == FrameKind::error);
  pack_key(pk, "channel");
  pk.pack_nil();
  pack_key(pk, "dlc");
  pk.pack_uint8(f.dlc);
  pack_key(pk, "data");
  pk.pack_bin(n);
  pk.pack_bin_body(reinterpret_cast<const char*>(f.data.data()), n);
  pack_key(pk, "is_fd");
  pk.pack_false();
  pack_key(pk, "bitrate_switch");
  pk.pack_false();
  pack_key(pk, "error_state_indicator");
  pk.pack_false();
  return w.used();
}

std::vector<std::uint8_t> encode(const Frame& f, double timestamp_s) {
  std::array<std::uint8_t, kMaxEncodedSize> buf{};
  const std::size_t n = encode(f, timestamp_s, buf);
  if (n == 0) throw std::invalid_argument("python-can msgpack: cannot encode invalid frame " + to_string(f));
  return {buf.begin(), buf.begin() + static_cast<std::ptrdiff_t>(n)};
}

DecodeStatus decode(std::span<const std::uint8_t> bytes, Decoded& out) noexcept {
  if (bytes.empty() || bytes.size() > kMaxDatagramSize) return DecodeStatus::malformed;
  Fields f;
  Visitor v(f);
  std::size_t off = 0;
  bool parsed = false;
  try {
    parsed = msgpack::parse(reinterpret_cast<const char*>(bytes.data()), bytes.size(), off, v);
  } catch (...) {  // msgpack-cxx throws on a few size overflows; the parser stack may throw bad_alloc
    return DecodeStatus::malformed;
  }
  if (v.status() != DecodeStatus::ok) return v.status();
  if (!parsed || off != bytes.size()) return DecodeStatus::malformed;
  const DecodeStatus s = validate(f);
  if (s != DecodeStatus::ok) return s;

  Frame& fr = out.frame;
  fr = Frame{};
  fr.id = static_cast<std::uint32_t>(f.arbitration_id);
  fr.extended = f.is_extended_id;
  fr.kind = f.is_remote_frame ? FrameKind::remote : f.is_error_frame ? FrameKind::error : FrameKind::data;
  fr.dlc = static_cast<std::uint8_t>(f.has_dlc ? f.dlc : f.data_len);
  if (!f.is_remote_frame) std::copy_n(f.data.begin(), fr.dlc, fr.data.begin());
  out.timestamp = f.timestamp;
  return DecodeStatus::ok;
}

}  // namespace omnitwin::can::msgpack_wire
