// libFuzzer target for controller/sim_clock: the sim-clock channel's 96-byte record decoder.
//
// decode() sees the input twice: as it is (so every length reaches the size check) and cut or
// zero-padded to exactly kMessageSize bytes (so the fuzzer need not find the length before it
// can explore the header and bodies). Properties checked on both: decode() returns (never
// throws, no UB: ASan/UBSan), an error has a name, and whatever decodes re-encodes to exactly
// the input bytes (the codec is a bijection on the records it accepts, so decoding those bytes
// again gives the same message). Trap on any mismatch.
//
//   clang++ -std=c++20 -g -O1 -fsanitize=fuzzer,address,undefined -I. \
//     fuzz/sim_clock_fuzz.cpp controller/sim_clock.cpp
//   ./a.out -max_total_time=30
#include "controller/sim_clock.hpp"

#include <algorithm>
#include <cstring>

using namespace omnitwin::simclock;

namespace {

// Checks one decode of `size` bytes at `data`; traps when a property fails.
void check(const std::uint8_t* data, std::size_t size) {
  const auto d = decode(data, size);
  if (const auto* e = std::get_if<DecodeError>(&d)) {
    if (to_string(*e) == nullptr) __builtin_trap();
    return;
  }
  // Byte equality also covers NaN poses, which compare unequal as doubles.
  const auto bytes = encode(std::get<Message>(d));
  if (size != bytes.size() || std::memcmp(bytes.data(), data, size) != 0) __builtin_trap();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // As given, then fitted to one record.
  check(data, size);
  std::uint8_t record[kMessageSize] = {};
  std::memcpy(record, data, std::min(size, kMessageSize));
  check(record, kMessageSize);
  return 0;
}
