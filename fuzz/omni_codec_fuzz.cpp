// libFuzzer target for bus_emulators/omni/omni_codec: the Omni application protocol decoder.
//
// The input is read as a raw frame: bytes 0–3 identifier (little-endian, any 32-bit value),
// byte 4 flags (bit 0 extended, bits 1–2 kind: 0 data, 1 remote, 2 error, 3 an out-of-range
// kind value), byte 5 DLC (any value, also > 8), then up to 8 data bytes (missing ones 0).
// Properties checked on every input: decode() returns (never throws, no UB: ASan/UBSan), an
// error has a name, and whatever decodes re-encodes to exactly the same frame (identifier,
// format, kind, DLC, data bytes) which decodes to the same message. Abort on any mismatch.
//
//   clang++ -std=c++20 -g -O1 -fsanitize=fuzzer,address,undefined -I. \
//     fuzz/omni_codec_fuzz.cpp bus_emulators/omni/omni_codec.cpp bus_emulators/can/can_frame.cpp -lfmt
//   ./a.out -max_total_time=30
#include "bus_emulators/omni/omni_codec.hpp"

#include <cstdlib>

using namespace omnitwin;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  auto byte = [&](std::size_t i) -> std::uint8_t { return i < size ? data[i] : 0; };
  can::Frame f;
  f.id = static_cast<std::uint32_t>(byte(0)) | static_cast<std::uint32_t>(byte(1)) << 8 |
         static_cast<std::uint32_t>(byte(2)) << 16 | static_cast<std::uint32_t>(byte(3)) << 24;
  f.extended = (byte(4) & 1u) != 0;
  const unsigned kind = (byte(4) >> 1) & 3u;
  f.kind = kind == 3 ? static_cast<can::FrameKind>(0x7F) : static_cast<can::FrameKind>(kind);
  f.dlc = byte(5);
  for (std::size_t i = 0; i < 8; ++i) f.data[i] = byte(6 + i);

  const omni::DecodeResult d = omni::decode(f);
  if (const auto* e = std::get_if<omni::DecodeError>(&d)) {
    if (omni::to_string(*e) == nullptr) std::abort();
    return 0;
  }
  const omni::Message& m = std::get<omni::Message>(d);
  const omni::EncodeResult e = omni::encode(m);
  const auto* g = std::get_if<can::Frame>(&e);
  if (g == nullptr) std::abort();
  if (!(*g == f) || !g->valid() || g->extended) std::abort();
  const omni::DecodeResult again = omni::decode(*g);
  const auto* m2 = std::get_if<omni::Message>(&again);
  if (m2 == nullptr || !(*m2 == m)) std::abort();
  return 0;
}
