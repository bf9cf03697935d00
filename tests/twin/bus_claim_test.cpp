// Tests twin/bus_claim: one twin per bus on this host. A claim on a key is refused to anyone
// else while held (BusInUse naming the holder's pid, from this process or another), is let go
// when its owner is destroyed or its process dies (killed, no clean-up), and different keys do
// not collide. Each test uses keys of its own (its pid in them), so parallel test processes
// never meet.
#include "twin/bus_claim.hpp"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <fmt/format.h>

#include <memory>
#include <string>

namespace omnitwin::twin {
namespace {

std::string key(const std::string& what) { return fmt::format("udp:239.74.163.2:{}-test-{}", what, ::getpid()); }

TEST(BusClaim, ASecondClaimOnTheSameBusIsRefusedNamingTheHolder) {
  const BusClaim first(key("a"));
  try {
    BusClaim second(key("a"));
    FAIL() << "a second claim was granted";
  } catch (const BusInUse& e) {
    EXPECT_EQ(e.pid, ::getpid());
    EXPECT_NE(std::string(e.what()).find(fmt::format("is in use by another twin (pid {})", ::getpid())),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find(key("a")), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(BusClaim other(key("b")));  // another bus
}

// Refusals do not pile up: each names the holder at once. The holder never accepts, and its
// queue of one was full after two lookups: the third refused run hung until the holder ended
// (found in review).
TEST(BusClaim, ManyRefusalsInARowEachNameTheHolderAtOnce) {
  const BusClaim first(key("many"));
  for (int i = 0; i < 20; ++i) {
    try {
      BusClaim again(key("many"));
      ADD_FAILURE() << "granted";
    } catch (const BusInUse& e) {
      EXPECT_EQ(e.pid, ::getpid()) << i << ": " << e.what();
    }
  }
}

// Both ends of a link the scenario names are claimed, each once; other specs are not.
TEST(BusClaim, BothNamedInterfacesOfALinkAreClaimed) {
  std::vector<std::unique_ptr<BusClaim>> claims;
  const std::string a = fmt::format("raw:rvA{}", ::getpid()), b = fmt::format("raw:rvB{}", ::getpid());
  claim_interfaces(claims, {a + "?x=1", b, a, "udp:127.0.0.1:5", ""});
  ASSERT_EQ(claims.size(), 2u);
  EXPECT_EQ(claims[0]->key(), a);
  EXPECT_EQ(claims[1]->key(), b);
  std::vector<std::unique_ptr<BusClaim>> swapped;
  EXPECT_THROW(claim_interfaces(swapped, {b, a}), BusInUse);  // the other end of the same link
}

TEST(BusClaim, AClaimIsLetGoWithItsOwner) {
  { const BusClaim c(key("c")); }
  EXPECT_NO_THROW(BusClaim again(key("c")));
}

// Held by another process: refused with that process's pid; once it is killed (SIGKILL: no
// destructor runs), the bus is free again.
TEST(BusClaim, AClaimHeldByAnotherProcessIsRefusedAndFreedWhenItIsKilled) {
  const std::string bus = key("d");  // the parent's pid in it, in the child too
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(ready[0]);
    BusClaim held(bus);
    const char ok = 1;
    if (::write(ready[1], &ok, 1) != 1) ::_exit(2);
    ::pause();
    ::_exit(0);
  }
  ::close(ready[1]);
  char ok = 0;
  ASSERT_EQ(::read(ready[0], &ok, 1), 1);
  ::close(ready[0]);
  try {
    BusClaim mine(bus);
    ADD_FAILURE() << "granted while another process holds it";
  } catch (const BusInUse& e) {
    EXPECT_EQ(e.pid, child) << e.what();
  }
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
  EXPECT_NO_THROW(BusClaim mine(key("d")));
}

TEST(BusClaim, ALongKeyIsHashedIntoTheAbstractNamesRoom) {
  const std::string longer(300, 'x');
  const std::string name = bus_claim_name(longer);
  EXPECT_LE(name.size(), 107u);
  EXPECT_NE(name, bus_claim_name(longer + "y"));
  const BusClaim c(longer + std::to_string(::getpid()));
  EXPECT_THROW(BusClaim again(longer + std::to_string(::getpid())), BusInUse);
}

}  // namespace
}  // namespace omnitwin::twin
