// bus_emulators/can — receive path of the Philips SJA1000 stand-alone CAN controller in
// PeliCAN mode (the slave node's controller in seed 002, fig. 4-6/4-7).
//
// Models what the 8051 firmware sees of reception: the acceptance filter (ACR0..3 / AMR0..3,
// single- or dual-filter mode, bit mapping of the SJA1000 data sheet §6.4.15), the 64-byte
// receive FIFO (3 + data bytes per standard message, 5 + data bytes per extended message),
// the RX message counter (RMC), receive-buffer status (RBS), data-overrun status (DOS, set
// when an accepted message does not fit; cleared only by the clear-data-overrun command),
// release-receive-buffer, and the receive / data-overrun interrupts (RI / DOI) with the INT
// line. Frames come in from the bus core already complete; nothing here touches sockets or
// a clock (a receive timestamp, if wanted, is passed in by the caller in ns).
//
// Fixed configuration (filter mode, ACR/AMR, interrupt enables) set at construction — the
// chip only accepts them in reset mode; everything else is run-time state. No allocation
// after construction; every member function is real-time safe unless noted.
#pragma once

#include <array>
#include <cstdint>
#include <functional>

#include "bus_emulators/can/can_frame.hpp"

namespace omnitwin::can {

// MOD.3 AFM: 1 = one long 32-bit filter ("single"), 0 = two short filters ("dual").
enum class Sja1000FilterMode : std::uint8_t { single, dual };

struct Sja1000Config {
  Sja1000FilterMode mode = Sja1000FilterMode::single;
  // ACR0..ACR3 (CAN addresses 16..19 in reset mode): the bit pattern to match.
  std::array<std::uint8_t, 4> acr{0, 0, 0, 0};
  // AMR0..AMR3 (CAN addresses 20..23): 1 = "don't care", 0 = the bit must equal the ACR bit.
  // The default accepts every message.
  std::array<std::uint8_t, 4> amr{0xFF, 0xFF, 0xFF, 0xFF};
  bool receive_interrupt_enable = true;   // IER.0 RIE
  bool overrun_interrupt_enable = true;   // IER.3 DOIE
};

// The acceptance test alone, as the data sheet maps the message bits onto ACR/AMR:
//  single, standard: ACR0 = ID.28..21, ACR1.7..5 = ID.20..18, ACR1.4 = RTR (ACR1.3..0 unused),
//                    ACR2 = data byte 1, ACR3 = data byte 2;
//  single, extended: ACR0..ACR2 = ID.28..5, ACR3.7..3 = ID.4..0, ACR3.2 = RTR (ACR3.1..0 unused);
//  dual, standard:   filter 1 = ACR0, ACR1.7..4 (ID.28..18, RTR), ACR1.3..0 = data byte 1
//                    upper nibble, ACR3.3..0 = data byte 1 lower nibble; filter 2 = ACR2,
//                    ACR3.7..4 (ID.28..18, RTR);
//  dual, extended:   filter 1 = ACR0, ACR1 = ID.28..13; filter 2 = ACR2, ACR3 = ID.28..13.
// A standard identifier's 11 bits are ID.28..ID.18 in the data sheet's numbering. Data bytes
// that the message does not carry (remote frame, or DLC 0 / 1) are not compared: such a
// message passes on its identifier and RTR bit. Error frames and invalid frames never pass.
// Real-time safe.
bool sja1000_accepts(const Sja1000Config& config, const Frame& frame);

// Bytes a message occupies in the 64-byte RX FIFO: frame information + 2 identifier bytes
// (standard) or + 4 (extended), plus the stored data bytes (none for a remote frame, at most
// 8 however large the DLC). Real-time safe.
int sja1000_fifo_cost(const Frame& frame);

class Sja1000 {
 public:
  static constexpr int kFifoBytes = 64;
  // Smallest message costs 3 bytes, so at most 21 fit at once.
  static constexpr int kMaxMessages = kFifoBytes / 3;

  enum class RxStatus : std::uint8_t {
    accepted,  // passed the filter and stored in the FIFO
    filtered,  // rejected by the acceptance filter (not an error)
    overrun,   // accepted but did not fit: message lost, DOS set
    invalid,   // error frame or identifier/DLC out of range: never stored, never counted
  };

  struct Message {
    Frame frame;                 // as received (identifier, format, RTR, DLC, data bytes)
    std::uint64_t rx_time_ns = 0;  // caller-supplied receive time [ns]; 0 if unused
  };

  struct Stats {
    std::uint64_t accepted = 0;  // messages stored in the FIFO
    std::uint64_t filtered = 0;  // messages dropped by the acceptance filter
    std::uint64_t overruns = 0;  // accepted messages lost because the FIFO was full
  };

  // Interrupt register (IR, CAN address 3) bits modelled here.
  static constexpr std::uint8_t kIrReceive = 0x01;       // IR.0 RI
  static constexpr std::uint8_t kIrDataOverrun = 0x08;   // IR.3 DOI

  // Called when the (active-low) INT line goes active, i.e. the first pending interrupt
  // appears while none was pending; the argument is the IR value at that moment. This is the
  // 8051's external-interrupt edge. Set up once, before frames flow; must not re-enter
  // receive() on this object.
  using InterruptHandler = std::function<void(std::uint8_t ir)>;

  explicit Sja1000(const Sja1000Config& config);

  // Would the acceptance filter take this frame? No state change. Real-time safe.
  bool accept(const Frame& frame) const { return sja1000_accepts(config_, frame); }

  // One frame completed on the bus: filter, then store in the FIFO if it fits, else set DOS
  // (and DOI if enabled) and drop it. `rx_time_ns` is stored with the message. Real-time safe.
  RxStatus receive(const Frame& frame, std::uint64_t rx_time_ns = 0);

  // The message in the receive buffer window (oldest in the FIFO), or nullptr when the FIFO
  // is empty. Valid until the next release(). Real-time safe.
  const Message* read() const;

  // Release-receive-buffer command (CMR.2 RRB): frees the oldest message's FIFO bytes and
  // decrements RMC. Returns false (no effect) when the FIFO is empty. Real-time safe.
  bool release();

  // Clear-data-overrun command (CMR.3 CDO): clears DOS. Real-time safe.
  void clear_data_overrun() { data_overrun_ = false; }

  // Read of the interrupt register: RI is a level (set while the FIFO holds a message and
  // RIE is set); DOI is cleared by this read. Real-time safe.
  std::uint8_t read_interrupt_register();

  // INT line active (any enabled interrupt pending). Real-time safe.
  bool interrupt_line() const { return pending_ir() != 0; }

  void set_interrupt_handler(InterruptHandler handler) { on_interrupt_ = std::move(handler); }

  bool receive_buffer_status() const { return count_ > 0; }  // SR.0 RBS
  bool data_overrun() const { return data_overrun_; }        // SR.1 DOS
  int rx_message_count() const { return count_; }            // RMC [messages]
  int fifo_bytes_used() const { return bytes_used_; }        // [bytes], 0..64
  int fifo_bytes_free() const { return kFifoBytes - bytes_used_; }

  const Stats& stats() const { return stats_; }
  const Sja1000Config& config() const { return config_; }

 private:
  std::uint8_t pending_ir() const;

  Sja1000Config config_;
  std::array<Message, kMaxMessages> ring_{};
  int head_ = 0;        // index of the oldest message
  int count_ = 0;       // RMC
  int bytes_used_ = 0;  // FIFO bytes held by stored messages
  bool data_overrun_ = false;  // DOS
  bool doi_ = false;           // IR.3 latched until IR is read
  Stats stats_;
  InterruptHandler on_interrupt_;
};

}  // namespace omnitwin::can
