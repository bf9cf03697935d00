// bus_emulators — the capture file of the Ethernet-framed buses (EtherCAT, MECHATROLINK-III):
// a LINKTYPE_ETHERNET pcap written through pcap_record's PcapFile (.part until complete),
// records padded to the 60-byte Ethernet minimum, counted per direction (0 out: a master sent
// it; 1 back: a slave did). Each bus's PcapWriter derives from it and adds its encapsulation
// (ethercat: a PDU behind an EtherCAT header; m3: a bare M-III frame behind station MACs).
// The pcap types stay opaque here, so users need not include <pcap.h>.
// Real-time: record() and write_ethernet() allocate nothing; opening may throw.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace omnitwin::bus_emulators {

class PcapFile;

class EthernetCapture {
 public:
  static constexpr std::size_t kMaxEthFrame = 1514;  // without the Ethernet FCS
  static constexpr int kLinkType = 1;                // LINKTYPE_ETHERNET / DLT_EN10MB

  // Creates `path`'s .part file (removing a stale `path`) and flushes its header; throws
  // std::runtime_error naming `path` on failure.
  EthernetCapture(const std::string& path, std::size_t buffer_bytes, bool flush_each_frame);
  ~EthernetCapture();
  EthernetCapture(const EthernetCapture&) = delete;
  EthernetCapture& operator=(const EthernetCapture&) = delete;

  // Hands buffered records to the kernel; the .part file is valid afterwards. false on an
  // I/O error (kept in error()).
  bool flush();
  // Flushes and closes; renames the .part file to path() when every write succeeded, else
  // removes it. Idempotent. True when path() now holds the complete capture.
  bool close();
  bool is_open() const;
  // false once a write, flush, sync or the final rename failed; error() then names the file
  // and the system's reason ("" while ok). Both stay readable after close().
  bool ok() const;
  std::string error() const;
  std::string part_path() const;  // where the capture is until close()

  // From now on records wait in a hold of `capacity` slots (allocated here) until release()
  // writes them in time order: a frame a delay fault made late is stamped later than frames
  // recorded after it, and a capture written in recording order went backwards in time. A
  // full hold is released whole first; close() releases what is left. Not real-time safe.
  void hold_in_time_order(std::size_t capacity);
  // Writes the held records stamped at or before upto_ns, sorted by time (stable: equal
  // stamps keep their recording order); later ones stay held. Real-time safe.
  void release(std::int64_t upto_ns);

  std::uint64_t written() const { return written_[0] + written_[1]; }
  std::uint64_t refused() const { return refused_; }
  const std::string& path() const { return path_; }

 protected:
  // Open and without a failed write.
  bool writable() const;
  // The frame being built (kMaxEthFrame bytes).
  std::uint8_t* frame() { return frame_.data(); }
  // Records the first `size` bytes of frame() at t [ns] in direction dir (0 out, 1 back),
  // zero-padded to 60 bytes.
  bool record(std::size_t size, std::int64_t t_ns, int dir);
  // A whole Ethernet frame as it is (over kMaxEthFrame bytes: refused and counted).
  bool write_ethernet(std::span<const std::uint8_t> eth_frame, std::int64_t t_ns, int dir);
  void refuse() { ++refused_; }
  std::uint64_t written_in(int dir) const { return written_[dir]; }

 private:
  std::string path_;
  bool flush_each_frame_;
  std::unique_ptr<PcapFile> file_;
  std::array<std::uint8_t, kMaxEthFrame> frame_{};
  struct Held {  // a record waiting for release()
    std::int64_t t_ns = 0;
    int dir = 0;
    std::size_t size = 0;
    std::array<std::uint8_t, kMaxEthFrame> bytes{};
  };
  std::vector<Held> held_, spare_;  // empty: records are written as they come
  std::size_t held_count_ = 0;
  std::vector<std::size_t> order_;  // release()'s sort, allocated with held_
  bool dump(const std::uint8_t* data, std::size_t size, std::int64_t t_ns, int dir);
  std::uint64_t written_[2] = {0, 0};
  std::uint64_t refused_ = 0;
};

}  // namespace omnitwin::bus_emulators
