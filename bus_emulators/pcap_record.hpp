// bus_emulators — the record header every bus's pcap writer shares: a simulated time in
// nanoseconds as a nanosecond-precision pcap timestamp. Header-only; real-time safe.
#pragma once

#include <pcap/pcap.h>

#include <cstdint>

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

}  // namespace omnitwin::bus_emulators
