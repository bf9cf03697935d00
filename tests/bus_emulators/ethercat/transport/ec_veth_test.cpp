// Tests bus_emulators/ethercat/transport/ec_veth.hpp: a VethPair creates two connected, up
// interfaces (up as the kernel sees it: operstate up and a queue discipline, so the first frame
// sent is not dropped) with unique names of at most 15 characters and IPv6 off, and deletes them when it goes away (also when
// the test using it fails: destruction is all it takes); a pair left by a process that is gone
// (SIGKILL) is deleted by the next one made, a live process's is not.
#include "tests/support/veth.hpp"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace omnitwin::testing {
namespace {

// The output of a shell command.
std::string output_of(const std::string& cmd) {
  std::string out;
  if (FILE* p = ::popen((cmd + " 2>&1").c_str(), "r")) {
    char buf[256];
    while (std::fgets(buf, sizeof buf, p)) out += buf;
    ::pclose(p);
  }
  return out;
}

std::string read_line(const std::string& path) {
  std::ifstream f(path);
  std::string s;
  std::getline(f, s);
  return s;
}

TEST(VethPair, CreatedUpUniqueAndGoneAfterwards) {
  if (const auto why = VethPair::unavailable_reason()) GTEST_SKIP() << *why;
  std::string a, b;
  {
    VethPair p;
    VethPair q;
    a = p.a();
    b = p.b();
    EXPECT_LE(a.size(), 15u);
    EXPECT_LE(b.size(), 15u);
    EXPECT_NE(a, b);
    EXPECT_NE(p.a(), q.a());
    EXPECT_NE(p.b(), q.b());
    EXPECT_TRUE(VethPair::exists(a));
    EXPECT_TRUE(VethPair::exists(b));
    // Joined to each other: each end's peer index is the other's index.
    EXPECT_EQ(read_line("/sys/class/net/" + a + "/iflink"), read_line("/sys/class/net/" + b + "/ifindex"));
    EXPECT_EQ(read_line("/sys/class/net/" + b + "/iflink"), read_line("/sys/class/net/" + a + "/ifindex"));
    EXPECT_EQ(read_line("/sys/class/net/" + a + "/operstate"), "up");
    EXPECT_EQ(read_line("/sys/class/net/" + b + "/operstate"), "up");
    for (const std::string& n : {a, b}) {  // the kernel's "noop" until its link-watch work ran
      const std::string link = output_of("PATH=/usr/sbin:/sbin:$PATH ip -o link show dev " + n);
      EXPECT_NE(link.find(" qdisc "), std::string::npos) << link;
      EXPECT_EQ(link.find("qdisc noop"), std::string::npos) << link;
    }
    if (std::filesystem::exists("/proc/sys/net/ipv6")) {  // only where the kernel has IPv6
      EXPECT_EQ(read_line("/proc/sys/net/ipv6/conf/" + a + "/disable_ipv6"), "1");
      EXPECT_EQ(read_line("/proc/sys/net/ipv6/conf/" + b + "/disable_ipv6"), "1");
    }
    p.set_address(a, "00:00:5e:00:53:07");
    EXPECT_EQ(read_line("/sys/class/net/" + a + "/address"), "00:00:5e:00:53:07");
  }
  EXPECT_FALSE(VethPair::exists(a));
  EXPECT_FALSE(VethPair::exists(b));
}

TEST(VethPair, BadAddressIsAClearError) {
  if (const auto why = VethPair::unavailable_reason()) GTEST_SKIP() << *why;
  VethPair p;
  EXPECT_THROW(p.set_address(p.a(), "zz:zz"), std::runtime_error);
}

// A twin killed with SIGKILL runs no destructor: its pair stayed for good (found in review).
// The next VethPair deletes pairs whose alias names a process that is gone, and only those.
TEST(VethPair, APairLeftByAProcessThatIsGoneIsDeletedByTheNextOne) {
  if (const auto why = VethPair::unavailable_reason()) GTEST_SKIP() << *why;
  const pid_t dead = ::fork();
  if (dead == 0) ::_exit(0);
  ASSERT_GT(dead, 0);
  ::waitpid(dead, nullptr, 0);  // reaped: no such process any more
  const std::string ip = ::access("/usr/sbin/ip", X_OK) == 0 ? "/usr/sbin/ip" : "ip";
  const std::string tag = std::to_string(::getpid() % 1000000);
  const std::string stale = "otsa" + tag, live = "otli" + tag, other = "otot" + tag;
  struct stat ns {};
  ASSERT_EQ(::stat("/proc/self/ns/pid", &ns), 0);
  const std::string here = "omnitwin-pid-" + std::to_string(ns.st_ino) + "-";
  auto make = [&](const std::string& base, const std::string& alias) {
    ASSERT_EQ(std::system((ip + " link add " + base + "a type veth peer name " + base + "b").c_str()), 0);
    ASSERT_EQ(std::system((ip + " link set dev " + base + "a alias " + alias).c_str()), 0);
  };
  make(stale, here + std::to_string(dead));
  make(live, here + std::to_string(::getpid()));
  // A dead pid's pair of another PID namespace (a container on the host's network): its pid
  // means nothing here, so it is kept (it was deleted; found in review).
  make(other, "omnitwin-pid-1-" + std::to_string(dead));
  ASSERT_TRUE(VethPair::exists(stale + "a"));
  {
    VethPair p;
    EXPECT_FALSE(VethPair::exists(stale + "a"));
    EXPECT_FALSE(VethPair::exists(stale + "b"));
    EXPECT_TRUE(VethPair::exists(live + "a"));  // its process (this one) lives
    EXPECT_TRUE(VethPair::exists(other + "a"));
    EXPECT_EQ(read_line("/sys/class/net/" + p.a() + "/ifalias"), here + std::to_string(::getpid()));
  }
  std::system((ip + " link del " + live + "a").c_str());
  std::system((ip + " link del " + other + "a").c_str());
  std::system((ip + " link del " + stale + "a 2>/dev/null").c_str());
}

}  // namespace
}  // namespace omnitwin::testing
