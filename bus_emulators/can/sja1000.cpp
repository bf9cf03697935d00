// bus_emulators/can — SJA1000 (PeliCAN) receive path; see sja1000.hpp.
#include "bus_emulators/can/sja1000.hpp"

#include <utility>

namespace omnitwin::can {
namespace {

// True when every bit of `message` equals the ACR bit wherever the AMR bit is 0.
constexpr bool match(std::uint8_t message, std::uint8_t acr, std::uint8_t amr) {
  return ((message ^ acr) & static_cast<std::uint8_t>(~amr)) == 0;
}

bool is_message(const Frame& f) {
  return f.kind != FrameKind::error && f.valid();
}

}  // namespace

bool sja1000_accepts(const Sja1000Config& c, const Frame& f) {
  if (!is_message(f)) return false;
  const auto& acr = c.acr;
  const auto& amr = c.amr;
  const std::uint8_t rtr = f.kind == FrameKind::remote ? 1 : 0;
  const int n_data = f.payload_size();  // 0 for remote frames
  const bool has_byte1 = n_data >= 1;
  const bool has_byte2 = n_data >= 2;

  if (!f.extended) {
    // The receive-buffer layout: ID.28..21 | ID.20..18, RTR, 0000 | data 1 | data 2.
    const auto id_hi = static_cast<std::uint8_t>((f.id >> 3) & 0xFF);
    const auto id_lo = static_cast<std::uint8_t>(((f.id & 0x7) << 5) | (rtr << 4));
    const std::uint8_t d1 = f.data[0];
    const std::uint8_t d2 = f.data[1];
    if (c.mode == Sja1000FilterMode::single) {
      return match(id_hi, acr[0], amr[0]) &&
             match(id_lo, acr[1], static_cast<std::uint8_t>(amr[1] | 0x0F)) &&  // .3..0 unused
             (!has_byte1 || match(d1, acr[2], amr[2])) &&
             (!has_byte2 || match(d2, acr[3], amr[3]));
    }
    const bool f1 = match(id_hi, acr[0], amr[0]) &&
                    match(id_lo, acr[1], static_cast<std::uint8_t>(amr[1] | 0x0F)) &&
                    (!has_byte1 ||
                     (match(static_cast<std::uint8_t>(d1 >> 4), acr[1] & 0x0F,
                            static_cast<std::uint8_t>(amr[1] | 0xF0)) &&
                      match(static_cast<std::uint8_t>(d1 & 0x0F), acr[3] & 0x0F,
                            static_cast<std::uint8_t>(amr[3] | 0xF0))));
    const bool f2 = match(id_hi, acr[2], amr[2]) &&
                    match(id_lo, acr[3], static_cast<std::uint8_t>(amr[3] | 0x0F));
    return f1 || f2;
  }

  // Extended: ID.28..21 | ID.20..13 | ID.12..5 | ID.4..0, RTR, 00.
  const auto b0 = static_cast<std::uint8_t>((f.id >> 21) & 0xFF);
  const auto b1 = static_cast<std::uint8_t>((f.id >> 13) & 0xFF);
  const auto b2 = static_cast<std::uint8_t>((f.id >> 5) & 0xFF);
  const auto b3 = static_cast<std::uint8_t>(((f.id & 0x1F) << 3) | (rtr << 2));
  if (c.mode == Sja1000FilterMode::single) {
    return match(b0, acr[0], amr[0]) && match(b1, acr[1], amr[1]) && match(b2, acr[2], amr[2]) &&
           match(b3, acr[3], static_cast<std::uint8_t>(amr[3] | 0x03));  // .1..0 unused
  }
  const bool f1 = match(b0, acr[0], amr[0]) && match(b1, acr[1], amr[1]);
  const bool f2 = match(b0, acr[2], amr[2]) && match(b1, acr[3], amr[3]);
  return f1 || f2;
}

int sja1000_fifo_cost(const Frame& f) { return (f.extended ? 5 : 3) + f.payload_size(); }

Sja1000::Sja1000(const Sja1000Config& config) : config_(config) {}

std::uint8_t Sja1000::pending_ir() const {
  std::uint8_t ir = 0;
  if (config_.receive_interrupt_enable && count_ > 0) ir |= kIrReceive;
  if (doi_) ir |= kIrDataOverrun;
  return ir;
}

Sja1000::RxStatus Sja1000::receive(const Frame& frame, std::uint64_t rx_time_ns) {
  if (!is_message(frame)) return RxStatus::invalid;
  if (!sja1000_accepts(config_, frame)) {
    ++stats_.filtered;
    return RxStatus::filtered;
  }
  const bool line_before = interrupt_line();
  const int cost = sja1000_fifo_cost(frame);
  RxStatus status;
  if (bytes_used_ + cost > kFifoBytes || count_ >= kMaxMessages) {
    // DOI is raised on the 0 -> 1 transition of DOS only.
    if (!data_overrun_ && config_.overrun_interrupt_enable) doi_ = true;
    data_overrun_ = true;
    ++stats_.overruns;
    status = RxStatus::overrun;
  } else {
    Message& m = ring_[static_cast<std::size_t>((head_ + count_) % kMaxMessages)];
    m.frame = frame;
    m.rx_time_ns = rx_time_ns;
    ++count_;
    bytes_used_ += cost;
    ++stats_.accepted;
    status = RxStatus::accepted;
  }
  if (!line_before && interrupt_line() && on_interrupt_) on_interrupt_(pending_ir());
  return status;
}

const Sja1000::Message* Sja1000::read() const {
  return count_ > 0 ? &ring_[static_cast<std::size_t>(head_)] : nullptr;
}

bool Sja1000::release() {
  if (count_ == 0) return false;
  bytes_used_ -= sja1000_fifo_cost(ring_[static_cast<std::size_t>(head_)].frame);
  head_ = (head_ + 1) % kMaxMessages;
  --count_;
  return true;
}

std::uint8_t Sja1000::read_interrupt_register() {
  const std::uint8_t ir = pending_ir();
  doi_ = false;  // every IR bit but RI is cleared by the read
  return ir;
}

}  // namespace omnitwin::can
