// bus_emulators/ethercat/device — the CoE (CANopen over EtherCAT) mailbox server of a slave.
//
// Takes whole SM0 mailbox writes and produces the SM1 replies: SDO upload and download
// (expedited ≤ 4 bytes, normal, segmented with toggle and last-segment bits), complete access
// when advertised, SDO aborts (in an SDO *request* service, command 0x80, u32 SdoAbort), and
// the SDO information service (object list by list type, fragmented; object description;
// entry description; error), and emergency messages the firmware posts. Mailbox types other than CoE and malformed headers get a mailbox
// error reply (type 0). A request whose mailbox counter (1–7) equals the previous request's
// is a repeat and is never executed again: when the previous replies have all been read (the
// master lost the reply on its way back) they are queued again; while one is still unread
// (queued here, or in SM1 as the caller says) nothing is added, so the master does not find a
// stale duplicate in SM1 after its next request.
//
// States of the SDO server (one transfer at a time; every request outside these is a new one):
//   idle        — initiate requests accepted.
//   downloading — after a normal download initiate whose data did not fit: download segment
//                 requests with alternating toggle (first 0) until the last-segment bit;
//                 anything else aborts the transfer (and is then handled as a new request).
//   uploading   — after an upload initiate whose data did not fit: upload segment requests
//                 with alternating toggle until the last segment has been sent.
// Replies go into a fixed queue (the slave posts them one by one while SM1 empties); memory
// is allocated at construction only. No throw.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "bus_emulators/ethercat/device/ec_mailbox.hpp"
#include "bus_emulators/ethercat/device/ec_od.hpp"

namespace omnitwin::ethercat {

namespace coe {
inline constexpr std::uint16_t svc_emergency = 1, svc_sdo_request = 2, svc_sdo_response = 3, svc_sdo_info = 8;
inline constexpr std::uint8_t info_list_req = 0x01, info_list_rsp = 0x02, info_obj_req = 0x03, info_obj_rsp = 0x04,
                              info_entry_req = 0x05, info_entry_rsp = 0x06, info_error = 0x07;
}  // namespace coe

struct CoeServerConfig {
  bool sdo_info = true;
  bool complete_access = false;
  std::size_t mailbox_size = 128;   // SM1 length: the largest reply [bytes], >= 16
  std::size_t max_transfer = 4096;  // largest segmented transfer buffered [bytes]
  std::size_t queue = 64;           // replies the queue holds
};

struct CoeStats {
  std::uint64_t requests = 0;        // mailbox writes handled
  std::uint64_t repeats = 0;         // answered again from the last replies
  std::uint64_t aborts = 0;          // SDO aborts sent
  std::uint64_t mailbox_errors = 0;  // mailbox error replies sent
  std::uint64_t dropped_replies = 0; // queue full
  std::uint64_t emergencies = 0;     // emergency messages queued
};

class CoeServer {
 public:
  CoeServer(ObjectDictionary& od, const CoeServerConfig& config);

  // One whole mailbox written by the master (SM0 buffer) in the given state; reply_unread:
  // the caller still holds an unread reply (SM1 full). RT-safe apart from the OD's hooks.
  void on_mailbox(std::span<const std::uint8_t> mailbox, OdState state, bool reply_unread = false) noexcept;
  // Changes the reply size (the SM1 length the master configured), clamped to the buffers.
  void set_mailbox_size(std::size_t bytes) noexcept;
  // Drops pending replies and any transfer (INIT, power cycle).
  void reset() noexcept;

  // A CoE emergency (ETG.1000.6: CoE header service 1; error code LE16, error register,
  // 5 manufacturer bytes) queued behind the pending replies; false when the queue is full
  // (counted as dropped). It is not part of any request's replies, so a repeated request never
  // sends it again. RT-safe.
  bool post_emergency(std::uint16_t code, std::uint8_t error_register, const std::uint8_t (&data)[5]) noexcept;

  bool has_reply() const noexcept { return count_ > 0; }
  std::span<const std::uint8_t> front() const noexcept;  // header + data of the oldest reply
  void pop() noexcept;
  const CoeStats& stats() const noexcept { return stats_; }

 private:
  enum class Transfer : std::uint8_t { idle, downloading, uploading };
  struct Reply {
    std::vector<std::uint8_t> bytes;
    std::size_t size = 0;
  };
  std::uint8_t* begin_reply(std::size_t data_len, MailboxType type);  // nullptr when full
  void sdo(std::span<const std::uint8_t> p, OdState s);
  void sdo_info(std::span<const std::uint8_t> p);
  void abort(std::uint16_t index, std::uint8_t sub, SdoAbort code);
  void mailbox_error(MailboxError e);
  void info_error(SdoAbort code);
  void info_fragments(std::uint8_t opcode, std::span<const std::uint8_t> data);
  void upload_initiate(std::uint16_t index, std::uint8_t sub, bool ca, OdState s);
  void upload_segment(std::uint8_t cmd);
  void download_initiate(std::span<const std::uint8_t> p, OdState s);
  void download_segment(std::span<const std::uint8_t> p, std::uint8_t cmd, OdState s);
  SdoAbort commit_download(OdState s);

  ObjectDictionary& od_;
  CoeServerConfig cfg_;
  std::size_t mbx_size_;
  std::vector<Reply> queue_;
  std::size_t head_ = 0, count_ = 0;
  std::vector<Reply> last_;   // copies of the last request's replies, for repeats
  std::size_t last_n_ = 0;
  std::uint8_t last_counter_ = 0;
  std::uint8_t reply_counter_ = 0;
  Transfer transfer_ = Transfer::idle;
  std::uint16_t t_index_ = 0;
  std::uint8_t t_sub_ = 0;
  bool t_ca_ = false;
  std::uint8_t t_toggle_ = 0;
  std::vector<std::uint8_t> t_buf_;
  std::size_t t_size_ = 0, t_done_ = 0;
  std::vector<std::uint8_t> scratch_;
  CoeStats stats_;
};

}  // namespace omnitwin::ethercat
