// bus_emulators — what every bus's pcap writer shares: the record header (a simulated time in
// nanoseconds as a nanosecond-precision pcap timestamp) and PcapFile, the capture file that
// appears under its final name only when complete. Header-only.
//
// PcapFile writes DIR/.NAME.part while the run goes (a reader may look at it; every flush
// leaves it valid up to the last record) and renames it to DIR/NAME in close() only when
// every write, the flush and the fsync succeeded. A stale DIR/NAME from an earlier run is
// removed when the file is opened. The first write error (ENOSPC: a full disk) is kept as a
// status: later records are refused, close() removes the .part file (freeing the space the
// run's other records still need) and leaves DIR/NAME absent; ok()/error() say what happened.
// dump() and flush() never throw and make no system call: the file is write-behind
// (write_behind.hpp), so a disk that throttles or stalls writers never stalls the cyclic path
// that calls them. flush() is a record boundary: the .part file holds whole records up to it
// within the writer's period (20 ms), and a write error shows at a later dump/flush or close.
#pragma once

#include <pcap/pcap.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string>

#include "bus_emulators/write_behind.hpp"

namespace omnitwin::bus_emulators {

// The pcap record header for a `size`-byte record at t_ns [ns] (negative times floor to the
// second below). Files opened with nanosecond precision: libpcap writes tv_usec as nanoseconds.
inline pcap_pkthdr pcap_record_header(std::int64_t t_ns, std::uint32_t size) {
  std::int64_t sec = t_ns / 1'000'000'000;
  std::int64_t nsec = t_ns % 1'000'000'000;
  if (nsec < 0) {
    nsec += 1'000'000'000;
    --sec;
  }
  pcap_pkthdr h{};
  h.ts.tv_sec = static_cast<time_t>(sec);
  h.ts.tv_usec = static_cast<suseconds_t>(nsec);
  h.caplen = static_cast<bpf_u_int32>(size);
  h.len = static_cast<bpf_u_int32>(size);
  return h;
}

// "DIR/.NAME.part" beside DIR/NAME, so that the final rename stays within one file system.
inline std::string pcap_part_path(const std::string& path) {
  const std::filesystem::path p(path);
  return (p.parent_path() / ("." + p.filename().string() + ".part")).string();
}

// One capture file: DIR/.NAME.part while written, DIR/NAME once closed complete (see above).
class PcapFile {
 public:
  // Removes a stale `path`, creates its .part file (write-behind, fsynced on close) with a
  // nanosecond-precision header for `linktype` and flushes the header. buffer_bytes > 0 sets
  // the stdio buffer size. Throws std::runtime_error naming `path` when it cannot be created.
  PcapFile(const std::string& path, int linktype, std::size_t buffer_bytes)
      : path_(path), part_(pcap_part_path(path)) {
    std::error_code ec;
    std::filesystem::remove(path_, ec);  // an older capture must not pass for this run's
    pcap_ = pcap_open_dead_with_tstamp_precision(linktype, 65535, PCAP_TSTAMP_PRECISION_NANO);
    if (!pcap_) throw std::runtime_error("pcap: pcap_open_dead failed for " + path_);
    if (!file_.open(part_, "wb", WriteBehindOptions{.fsync_on_close = true}))
      open_failed("cannot create", std::strerror(errno));
    if (buffer_bytes > 0) std::setvbuf(file_.stream(), nullptr, _IOFBF, buffer_bytes);
    // The dumper is the stream itself (libpcap casts it); file_ owns and closes it.
    dumper_ = pcap_dump_fopen(pcap_, file_.stream());
    if (!dumper_) open_failed("cannot write", pcap_geterr(pcap_));
    if (!flush()) open_failed("cannot write", std::strerror(err_));
  }
  ~PcapFile() { close(); }
  PcapFile(const PcapFile&) = delete;
  PcapFile& operator=(const PcapFile&) = delete;

  // Appends one record; false once closed or failed (the first error is kept). RT-safe.
  bool dump(const pcap_pkthdr& h, const u_char* data) {
    if (!dumper_ || err_ != 0) return false;
    pcap_dump(reinterpret_cast<u_char*>(dumper_), &h, data);
    if (std::ferror(pcap_dump_file(dumper_))) return fail(errno, "cannot write");
    return true;
  }

  // A record boundary: hands buffered records to the writer thread, which writes them within
  // its period; the .part file is valid up to them then. RT-safe.
  bool flush() {
    if (!dumper_ || err_ != 0) return false;
    if (!file_.commit()) return fail(errno, "cannot write");
    return true;
  }

  // Flushes, syncs and closes; renames to the final name if nothing failed, else removes
  // the .part file. Idempotent. True when the final file is in place.
  bool close() {
    if (dumper_) {
      // Waits for the writer thread, fsyncs, closes (pcap_dump_close would be fclose alone).
      if (file_.close() != 0) fail(errno, "cannot write or sync");
      dumper_ = nullptr;
      if (err_ == 0 && std::rename(part_.c_str(), path_.c_str()) != 0) fail(errno, "cannot rename to the final name");
      if (err_ != 0) std::remove(part_.c_str());
      renamed_ = err_ == 0;
    }
    if (pcap_) pcap_close(pcap_);
    pcap_ = nullptr;
    return renamed_;
  }

  bool is_open() const { return dumper_ != nullptr; }
  bool ok() const { return err_ == 0; }
  // "" while ok; else one line naming the file, the step and the system's reason.
  std::string error() const {
    if (err_ == 0) return "";
    return "pcap " + path_ + ": " + what_ + " " + part_ + ": " + std::strerror(err_) +
           "; the capture is incomplete and is not kept";
  }
  const std::string& path() const { return path_; }
  const std::string& part_path() const { return part_; }

 private:
  // Keeps the first error (errno 0 counts as EIO); returns false.
  bool fail(int err, const char* what) {
    if (err_ == 0) {
      err_ = err != 0 ? err : EIO;
      what_ = what;
    }
    return false;
  }

  // Releases what the constructor opened and throws naming the file.
  [[noreturn]] void open_failed(const char* what, const std::string& why) {
    dumper_ = nullptr;
    file_.close();
    pcap_close(pcap_);
    std::remove(part_.c_str());
    throw std::runtime_error("pcap: " + std::string(what) + " " + path_ + " (as " + part_ + "): " + why);
  }

  std::string path_, part_;
  pcap_t* pcap_ = nullptr;
  WriteBehindFile file_;
  pcap_dumper_t* dumper_ = nullptr;
  int err_ = 0;
  const char* what_ = "";
  bool renamed_ = false;
};

}  // namespace omnitwin::bus_emulators
