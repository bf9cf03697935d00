// Tests controller/canopen/co_config: the CANopen master's configuration file refuses a
// master node ID that is also a wheel's (the drives would watch their own heartbeat for the
// master's) and a `tick` the master would ignore (it produces SYNC and ticks every cycle),
// each naming the file, line and key.
#include "controller/canopen/co_config.hpp"

#include <gtest/gtest.h>

#include <string>

namespace omnitwin::controller::canopen {
namespace {

// The message parse_co_config throws for `yaml` ("" when it does not throw).
std::string error_of(const std::string& yaml) {
  try {
    parse_co_config(yaml, "c.yaml", "");
  } catch (const CoConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(CoConfig, AMasterNodeIdThatIsAWheelsIsRefusedNamingFileLineAndKey) {
  EXPECT_EQ(error_of("eds: x.eds\nnodes: [1, 2, 3, 4]\nmaster_node_id: 3\n"),
            "c.yaml:3: master_node_id: 3 is also a wheel's node ID (the master needs one of its own)");
  // The default (127) against a wheel on 127: the nodes' line is named.
  EXPECT_NE(error_of("eds: x.eds\nnodes: [1, 2, 3, 127]\n").find("c.yaml:2: master_node_id: 127"), std::string::npos);
  EXPECT_EQ(error_of("eds: x.eds\nnodes: [1, 2, 3, 127]\nmaster_node_id: 0\n"), "");  // no heartbeat of its own
  EXPECT_EQ(error_of("eds: x.eds\nnodes: [1, 2, 3, 4]\nmaster_node_id: 5\n"), "");
}

TEST(CoConfig, ATickWithTheMasterProducingSyncIsRefused) {
  EXPECT_EQ(error_of("eds: x.eds\ntick: 0.01\n"),
            "c.yaml:2: tick: only with a wheel's drive as sync_producer (the master ticks every cycle)");
  EXPECT_EQ(error_of("eds: x.eds\nsync_producer: master\ntick: 0.01\n").find("c.yaml:3: tick:"), 0u);
  EXPECT_EQ(error_of("eds: x.eds\nsync_producer: 2\ntick: 0.01\n"), "");
}

}  // namespace
}  // namespace omnitwin::controller::canopen
