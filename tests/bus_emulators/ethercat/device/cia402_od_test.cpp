// Tests bus_emulators/ethercat/device/cia402_od: the CiA 402 objects bound into a CiA 301
// dictionary (the shipped drive ESI; the CANopen drive node binds the same way) accept only the
// option codes and homing methods the drive core implements — anything else is refused with
// 0x06090030 and leaves the drive's value as it was.
#include "bus_emulators/ethercat/device/cia402_od.hpp"

#include <gtest/gtest.h>

#include <string>

namespace omnitwin::ethercat {
namespace {

class Cia402Od : public ::testing::Test {
 protected:
  void SetUp() override {
    od.add_from_esi(load_esi(std::string(OMNITWIN_SOURCE_DIR) + "/models/ethercat/omnitwin_drive.xml").at(0));
    bind_cia402_objects(od, drive);
  }
  // An SDO write of `v` to index:0 in the entry's own size.
  SdoAbort write(std::uint16_t index, std::int64_t v) {
    const OdEntry* e = od.entry(index, 0);
    std::uint8_t b[8]{};
    for (std::size_t i = 0; i < e->bytes(); ++i) b[i] = static_cast<std::uint8_t>(static_cast<std::uint64_t>(v) >> (8 * i));
    return od.write(index, 0, OdState::preop, std::span<const std::uint8_t>(b, e->bytes()));
  }
  drive::Cia402Drive drive{drive::DriveConfig{}};
  ObjectDictionary od;
};

TEST_F(Cia402Od, QuickStopOptionAcceptsTheCodes0To8Only) {
  for (int v = 0; v <= 8; ++v) EXPECT_EQ(write(0x605A, v), SdoAbort::none) << v;
  EXPECT_EQ(write(0x605A, 9), SdoAbort::value_range);      // reserved
  EXPECT_EQ(write(0x605A, 32767), SdoAbort::value_range);  // reserved
  EXPECT_EQ(write(0x605A, -1), SdoAbort::value_range);     // manufacturer specific: none implemented
  EXPECT_EQ(drive.objects().quick_stop_option, 8);
}

TEST_F(Cia402Od, HaltOptionAcceptsTheTwoRampsOnly) {
  EXPECT_EQ(write(0x605D, 2), SdoAbort::none);
  EXPECT_EQ(write(0x605D, 1), SdoAbort::none);
  for (int v : {0, 3, 4, 5, -1}) EXPECT_EQ(write(0x605D, v), SdoAbort::value_range) << v;
  EXPECT_EQ(drive.objects().halt_option, 1);
}

TEST_F(Cia402Od, FaultReactionOptionAcceptsTheCodes0To4Only) {
  for (int v = 0; v <= 4; ++v) EXPECT_EQ(write(0x605E, v), SdoAbort::none) << v;
  for (int v : {5, 7, -1}) EXPECT_EQ(write(0x605E, v), SdoAbort::value_range) << v;
  EXPECT_EQ(drive.objects().fault_reaction_option, 4);
}

TEST_F(Cia402Od, HomingMethodAcceptsTheImplementedMethodsOnly) {
  for (int v : {1, 14, 17, 30, 33, 34, 35, 37}) EXPECT_EQ(write(0x6098, v), SdoAbort::none) << v;
  for (int v : {0, 15, 16, 31, 32, 36, 38, -1}) EXPECT_EQ(write(0x6098, v), SdoAbort::value_range) << v;
  EXPECT_EQ(drive.objects().homing_method, 37);
}

}  // namespace
}  // namespace omnitwin::ethercat
