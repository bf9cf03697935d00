// bus_emulators/canopen — SYNC and TIME (CiA 301 §7.2.5, §7.2.6): the SYNC producer (our master,
// or a node whose 0x1005 has the gen bit), SYNC decoding with the optional counter, and the
// TIME_OF_DAY stamp (ms after midnight, days since 1984-01-01) both ways.
//
// Protocol cores: time [ns] in, frames out through SendFn. Real-time safe.
#pragma once

#include <cstdint>
#include <optional>

#include "bus_emulators/canopen/co_types.hpp"

namespace omnitwin::canopen {

// SYNC producer. period_ns 0 = off. With a counter overflow value 2..240 (0x1019) every SYNC
// carries a 1-byte counter 1..overflow; 0 = no data (CiA 301: 1 and 241..255 are reserved).
struct SyncProducerConfig {
  std::uint32_t cob_id = cob::sync;
  SimTime period_ns = 0;
  std::uint8_t counter_overflow = 0;
};

class SyncProducer {
 public:
  explicit SyncProducer(SyncProducerConfig c = {}) : cfg_(c) {}
  void configure(const SyncProducerConfig& c) { cfg_ = c; }
  const SyncProducerConfig& config() const { return cfg_; }

  // Starts producing: the first SYNC at `first`; the counter restarts at 1.
  void start(SimTime first) { next_ = first, counter_ = 1, running_ = cfg_.period_ns > 0; }
  void stop() { running_ = false; }
  bool running() const { return running_; }
  // Sends the SYNCs due by now (each at its own due time). Returns how many.
  int on_time(SimTime now, const SendFn& send);
  // One SYNC now, outside the period (a master driven by its own cycle).
  bool send_one(SimTime now, const SendFn& send);
  SimTime next_due() const { return running_ ? next_ : -1; }
  std::uint64_t sent() const { return sent_; }

 private:
  SyncProducerConfig cfg_;
  SimTime next_ = 0;
  std::uint8_t counter_ = 1;
  bool running_ = false;
  std::uint64_t sent_ = 0;
};

// A SYNC frame on `cob_id`: true with counter 0 (none) or 1..240; false for another frame or
// a SYNC with a wrong length (the consumer counts those: CiA 301 asks for a length check).
enum class SyncDecode : std::uint8_t { not_sync, ok, bad_length };
SyncDecode decode_sync(const can::Frame& f, std::uint32_t cob_id, std::uint8_t expected_overflow,
                       std::uint8_t& counter);

// TIME_OF_DAY: milliseconds after midnight (28 bits) and days since 1984-01-01.
struct TimeOfDay {
  std::uint32_t ms = 0;
  std::uint16_t days = 0;
  // Nanoseconds since 1984-01-01 00:00.
  std::int64_t since_epoch_ns() const { return (static_cast<std::int64_t>(days) * 86'400'000 + ms) * 1'000'000; }
};
// Encodes into a 6-byte TIME frame on cob_id.
can::Frame encode_time(const TimeOfDay& t, std::uint32_t cob_id = cob::time);
// Decodes a TIME frame (6 bytes on cob_id); nullopt otherwise.
std::optional<TimeOfDay> decode_time(const can::Frame& f, std::uint32_t cob_id = cob::time);
// The stamp of ns since 1984-01-01.
TimeOfDay time_of_day(std::int64_t since_epoch_ns);

}  // namespace omnitwin::canopen
