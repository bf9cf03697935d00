// bus_emulators/canopen — SYNC and TIME (see co_sync.hpp).
#include "bus_emulators/canopen/co_sync.hpp"

namespace omnitwin::canopen {

bool SyncProducer::send_one(SimTime now, const SendFn& send) {
  const bool with_counter = cfg_.counter_overflow >= 2 && cfg_.counter_overflow <= 240;
  can::Frame f = frame11(cfg_.cob_id, with_counter ? 1 : 0);
  if (with_counter) {
    f.data[0] = counter_;
    counter_ = counter_ >= cfg_.counter_overflow ? 1 : static_cast<std::uint8_t>(counter_ + 1);
  }
  const bool ok = send(f, now);
  if (ok) ++sent_;
  return ok;
}

int SyncProducer::on_time(SimTime now, const SendFn& send) {
  int n = 0;
  while (running_ && next_ <= now) {
    send_one(next_, send);
    next_ += cfg_.period_ns;
    ++n;
  }
  return n;
}

SyncDecode decode_sync(const can::Frame& f, std::uint32_t cob_id, std::uint8_t expected_overflow,
                       std::uint8_t& counter) {
  if (f.extended || f.kind != can::FrameKind::data || f.id != (cob_id & cob::id_mask_11)) return SyncDecode::not_sync;
  const bool with_counter = expected_overflow >= 2 && expected_overflow <= 240;
  if (f.dlc != (with_counter ? 1 : 0)) return SyncDecode::bad_length;
  counter = with_counter ? f.data[0] : 0;
  return SyncDecode::ok;
}

can::Frame encode_time(const TimeOfDay& t, std::uint32_t cob_id) {
  can::Frame f = frame11(cob_id, 6);
  put_u32(f.data.data(), t.ms & 0x0FFF'FFFFu);
  put_u16(f.data.data() + 4, t.days);
  return f;
}

std::optional<TimeOfDay> decode_time(const can::Frame& f, std::uint32_t cob_id) {
  if (f.extended || f.kind != can::FrameKind::data || f.id != (cob_id & cob::id_mask_11) || f.dlc != 6) return std::nullopt;
  TimeOfDay t;
  t.ms = get_u32(f.data.data()) & 0x0FFF'FFFFu;
  t.days = get_u16(f.data.data() + 4);
  return t;
}

TimeOfDay time_of_day(std::int64_t since_epoch_ns) {
  const std::int64_t ms = since_epoch_ns / 1'000'000;
  TimeOfDay t;
  t.days = static_cast<std::uint16_t>(ms / 86'400'000);
  t.ms = static_cast<std::uint32_t>(ms % 86'400'000);
  return t;
}

}  // namespace omnitwin::canopen
