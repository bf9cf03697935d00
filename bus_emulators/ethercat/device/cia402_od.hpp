// bus_emulators/ethercat/device — binds the CiA 402 objects of one drive axis (drive::Objects)
// into a CiA 301 object dictionary, so that SDO access and PDOs read and write the drive core's
// own variables without copies. Shared by every bus whose dictionary is CiA 301's: the EtherCAT
// (CoE) drive slaves and the CANopen drive nodes (bus_emulators/canopen/co_drive).
//
// Set-up code (binding; installs check hooks: 0x6060 accepts only the modes the drive
// advertises in 0x6502, and 0 = none; 0x605A, 0x605D, 0x605E and 0x6098 only the option codes
// and homing methods the drive core implements — else 0x06090030).
#pragma once

#include <cstdint>

#include "bus_emulators/drive/cia402_drive.hpp"
#include "bus_emulators/ethercat/device/ec_od.hpp"

namespace omnitwin::ethercat {

// Binds every 0x6000-range object the dictionary has at index + `offset` (0x800 per axis for
// multi-axis devices) to `drive`'s objects. Entries the dictionary lacks are skipped. The drive
// must outlive the dictionary's use.
void bind_cia402_objects(ObjectDictionary& od, drive::Cia402Drive& drive, std::uint16_t offset = 0);

}  // namespace omnitwin::ethercat
