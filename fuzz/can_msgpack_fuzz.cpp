// libFuzzer target for bus_emulators/can/can_msgpack: python-can `udp_multicast` datagrams.
//
// Properties checked on every input: decode() returns (never throws, never reads outside the
// input: ASan/UBSan), and whatever decodes is a valid classic frame that survives
// encode -> decode unchanged (frame and timestamp bit-for-bit).
//
//   clang++ -std=c++20 -g -O1 -fsanitize=fuzzer,address,undefined -I. \
//     fuzz/can_msgpack_fuzz.cpp bus_emulators/can/can_msgpack.cpp bus_emulators/can/can_frame.cpp -lfmt
//   ./a.out -dict=fuzz/can_msgpack.dict -max_total_time=30
#include "bus_emulators/can/can_msgpack.hpp"

#include <cstdlib>
#include <cstring>

using namespace omnitwin::can;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  msgpack_wire::Decoded d;
  const auto status = msgpack_wire::decode({data, size}, d);
  if (status != msgpack_wire::DecodeStatus::ok) {
    if (msgpack_wire::to_string(status) == nullptr) std::abort();
    return 0;
  }
  if (!d.frame.valid()) std::abort();
  std::uint8_t buf[msgpack_wire::kMaxEncodedSize];
  const std::size_t n = msgpack_wire::encode(d.frame, d.timestamp, buf);
  if (n == 0) std::abort();
  msgpack_wire::Decoded again;
  if (msgpack_wire::decode({buf, n}, again) != msgpack_wire::DecodeStatus::ok) std::abort();
  if (!(again.frame == d.frame)) std::abort();
  if (std::memcmp(&again.timestamp, &d.timestamp, sizeof(double)) != 0) std::abort();
  return 0;
}
