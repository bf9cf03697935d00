// Tests twin/experiment_m3_latency (the m3-cycle study's event-driven part): the latencies
// our C1 master measures in event-driven mode equal the wire model's to the ns on a cascade
// and a star, grow with the slaves asked at once, and stay below the cyclic mode's shortest
// cycle at 64 bytes; the CSV and the README section carry every row.
#include <gtest/gtest.h>

#include "bus_emulators/mechatrolink3/m3_wire.hpp"
#include "twin/experiment.hpp"

namespace omnitwin::twin {
namespace {

TEST(M3Latency, EventDrivenLatencyEqualsTheWireModel) {
  const M3LatencyRow cascade = m3_event_latency(false, 4);
  ASSERT_TRUE(cascade.ok()) << cascade.why;
  // The farthest of four slaves on a 10 m cascade: TR_DLY 2 × (4 × 50 + 3 × 500) ns.
  EXPECT_EQ(cascade.idle_ns, 2 * (4 * 50 + 3 * 500) + 2 * m3::frame_time_ns(64) + 2'000);
  EXPECT_GT(cascade.all_ns, 3 * cascade.idle_ns) << "four exchanges one after the other";
  EXPECT_LT(cascade.all_ns, cascade.cyclic_ns);
  const M3LatencyRow star = m3_event_latency(true, 4);
  ASSERT_TRUE(star.ok()) << star.why;
  EXPECT_EQ(star.idle_ns, 2 * (50 + 500 + 50) + 2 * m3::frame_time_ns(64) + 2'000);
}

TEST(M3Latency, CsvAndSectionCarryEveryRow) {
  const std::vector<M3LatencyRow> rows = {m3_event_latency(false, 1), m3_event_latency(true, 2)};
  const std::string csv = m3_latency_csv(rows);
  EXPECT_NE(csv.find("cascade,1,"), std::string::npos) << csv;
  EXPECT_NE(csv.find("star,2,"), std::string::npos) << csv;
  const std::string md = m3_latency_section(rows);
  EXPECT_NE(md.find("| star | 2 |"), std::string::npos) << md;
  EXPECT_EQ(md.find("**"), std::string::npos) << "no failed row";
}

}  // namespace
}  // namespace omnitwin::twin
