// Test support — capture_records(): how many whole records a pcap file holds right now, -1
// while it does not hold even the file header. For captures a write-behind thread is still
// writing (pair it with eventually()); it asserts nothing, so polling it adds no failures.
#pragma once

#include <pcap/pcap.h>

#include <string>

namespace omnitwin::testing {

inline long capture_records(const std::string& path) {
  char err[PCAP_ERRBUF_SIZE];
  pcap_t* p = pcap_open_offline(path.c_str(), err);
  if (p == nullptr) return -1;
  long n = 0;
  pcap_pkthdr* h = nullptr;
  const u_char* data = nullptr;
  while (pcap_next_ex(p, &h, &data) == 1) ++n;
  pcap_close(p);
  return n;
}

}  // namespace omnitwin::testing
