// bus_emulators/ethercat — the ESC register map as named constants (physical addresses in the
// ESC's 64 KiB address space; registers 0x0000–0x0FFF, process RAM from 0x1000).
//
// Only addresses that the ESC core, its tests or a master touch are named; every other register
// address is plain stored memory. Values and bit meanings are those of facts/ethercat.md.
#pragma once

#include <cstdint>

namespace omnitwin::ethercat::reg {

// ---- ESC information (read-only) ----
inline constexpr std::uint16_t kType = 0x0000;           // u8
inline constexpr std::uint16_t kRevision = 0x0001;       // u8
inline constexpr std::uint16_t kBuild = 0x0002;          // u16
inline constexpr std::uint16_t kFmmuCount = 0x0004;      // u8
inline constexpr std::uint16_t kSmCount = 0x0005;        // u8
inline constexpr std::uint16_t kRamSize = 0x0006;        // u8, KiB
inline constexpr std::uint16_t kPortDescriptor = 0x0007; // u8, 2 bits per port (11 = MII)
inline constexpr std::uint16_t kFeatures = 0x0008;       // u16, bit 2 DC, bit 3 64-bit DC

// ---- station address ----
inline constexpr std::uint16_t kStationAddress = 0x0010;  // u16, written by the master
inline constexpr std::uint16_t kStationAlias = 0x0012;    // u16, loaded from SII word 4

inline constexpr std::uint16_t kWriteEnable = 0x0020;     // write register enable/protection
inline constexpr std::uint16_t kEscReset = 0x0040;

// ---- data link layer ----
inline constexpr std::uint16_t kDlControl = 0x0100;       // u32
inline constexpr std::uint16_t kDlControlAlias = 0x0103;  // bit 0: station alias enabled
inline constexpr std::uint16_t kDlStatus = 0x0110;        // u16
inline constexpr std::uint16_t kDlStatusLinkBit0 = 4;     // bit 4+p: physical link on port p
inline constexpr std::uint16_t kDlStatusLoopBit0 = 8;     // bit 8+2p: loop closed, 9+2p: communication

// ---- application layer ----
inline constexpr std::uint16_t kAlControl = 0x0120;       // u16, bits 0–3 state, bit 4 error ack
inline constexpr std::uint16_t kAlStatus = 0x0130;        // u16, state | 0x10 on error
inline constexpr std::uint16_t kAlStatusCode = 0x0134;    // u16
inline constexpr std::uint16_t kPdiControl = 0x0140;      // u8, from SII word 0
inline constexpr std::uint16_t kEscConfig = 0x0141;       // u8, from SII word 0 high byte
inline constexpr std::uint16_t kAlControlErrorAck = 0x10;
inline constexpr std::uint16_t kAlStatusError = 0x10;

// ---- interrupts ----
inline constexpr std::uint16_t kEcatEventMask = 0x0200;   // u16
inline constexpr std::uint16_t kAlEventMask = 0x0204;     // u32 (PDI)
inline constexpr std::uint16_t kEcatEventRequest = 0x0210;// u16
inline constexpr std::uint16_t kAlEventRequest = 0x0220;  // u32
inline constexpr std::uint16_t kEventDlStatus = 0x0004;   // ECAT event bits
inline constexpr std::uint16_t kEventAlStatus = 0x0008;
inline constexpr std::uint16_t kEventSm0 = 0x0010;        // << i for SM i (i < 8)

// ---- error counters (masters write 0 to reset: stored) ----
inline constexpr std::uint16_t kRxErrorCounter = 0x0300;  // 0x0300–0x030B
inline constexpr std::uint16_t kLostLinkCounter = 0x0310; // 0x0310–0x0313

// ---- watchdogs ----
inline constexpr std::uint16_t kWatchdogDivider = 0x0400;     // u16, (divider + 2) × 40 ns
inline constexpr std::uint16_t kWatchdogTimePdi = 0x0410;     // u16
inline constexpr std::uint16_t kWatchdogTimePd = 0x0420;      // u16, in divider units
inline constexpr std::uint16_t kWatchdogStatusPd = 0x0440;    // u16, bit 0: 1 = not expired
inline constexpr std::uint16_t kWatchdogCounterPd = 0x0442;   // u8
inline constexpr std::uint16_t kWatchdogCounterPdi = 0x0443;  // u8
inline constexpr std::uint16_t kDefaultWatchdogDivider = 0x09C2;  // 2498 → 100 µs
inline constexpr std::uint16_t kDefaultWatchdogTime = 0x03E8;     // 1000 → 100 ms

// ---- SII EEPROM interface ----
inline constexpr std::uint16_t kEepromConfig = 0x0500;    // u8, bit 0: owner (0 ECAT, 1 PDI)
inline constexpr std::uint16_t kEepromPdiAccess = 0x0501; // u8
inline constexpr std::uint16_t kEepromControl = 0x0502;   // u16 control/status
inline constexpr std::uint16_t kEepromAddress = 0x0504;   // u32, word address
inline constexpr std::uint16_t kEepromData = 0x0508;      // 4 or 8 bytes
inline constexpr std::uint16_t kEepromEnd = 0x0510;       // one past the interface
inline constexpr std::uint16_t kEepromWriteEnable = 0x0001;
inline constexpr std::uint16_t kEepromRead8 = 0x0040;     // 8-byte reads supported
inline constexpr std::uint16_t kEepromCmdMask = 0x0700;
inline constexpr std::uint16_t kEepromCmdRead = 0x0100;
inline constexpr std::uint16_t kEepromCmdWrite = 0x0200;
inline constexpr std::uint16_t kEepromCmdReload = 0x0400;
inline constexpr std::uint16_t kEepromErrChecksum = 0x0800;
inline constexpr std::uint16_t kEepromErrNack = 0x2000;
inline constexpr std::uint16_t kEepromErrWriteEnable = 0x4000;
inline constexpr std::uint16_t kEepromBusy = 0x8000;

// ---- MII management (stored) ----
inline constexpr std::uint16_t kMiiControl = 0x0510;

// ---- FMMUs and SyncManagers ----
inline constexpr std::uint16_t kFmmu0 = 0x0600;      // 16 bytes each
inline constexpr std::uint16_t kFmmuSize = 16;
inline constexpr std::uint16_t kFmmuEnd = 0x0700;
inline constexpr std::uint16_t kSm0 = 0x0800;        // 8 bytes each
inline constexpr std::uint16_t kSmSize = 8;
inline constexpr std::uint16_t kSmEnd = 0x0880;
inline constexpr std::uint16_t kSmStart = 0;         // offsets inside one SM block
inline constexpr std::uint16_t kSmLength = 2;
inline constexpr std::uint16_t kSmControl = 4;
inline constexpr std::uint16_t kSmStatus = 5;
inline constexpr std::uint16_t kSmActivate = 6;
inline constexpr std::uint16_t kSmPdiControl = 7;

// ---- distributed clocks ----
inline constexpr std::uint16_t kDcReceiveTimePort0 = 0x0900;  // u32 each, ports 0..3; BWR latches
inline constexpr std::uint16_t kDcReceiveTimePort1 = 0x0904;
inline constexpr std::uint16_t kDcReceiveTimePort2 = 0x0908;
inline constexpr std::uint16_t kDcReceiveTimePort3 = 0x090C;
inline constexpr std::uint16_t kDcSystemTime = 0x0910;        // u64 read: system time; write: drift sample
inline constexpr std::uint16_t kDcReceiveTimeEpu = 0x0918;    // u64 local time at port-0 receive
inline constexpr std::uint16_t kDcSystemTimeOffset = 0x0920;  // u64
inline constexpr std::uint16_t kDcSystemTimeDelay = 0x0928;   // u32
inline constexpr std::uint16_t kDcSystemTimeDiff = 0x092C;    // u32, bit 31: local smaller
inline constexpr std::uint16_t kDcSpeedCounterStart = 0x0930; // u16 (write resets the loop)
inline constexpr std::uint16_t kDcSpeedCounterDiff = 0x0932;  // i16
inline constexpr std::uint16_t kDcTimeDiffFilter = 0x0934;    // u8
inline constexpr std::uint16_t kDcSpeedFilter = 0x0935;       // u8
inline constexpr std::uint16_t kDcCyclicUnitControl = 0x0980; // u8
inline constexpr std::uint16_t kDcActivation = 0x0981;        // u8: bit 0 cyclic, 1 SYNC0, 2 SYNC1
inline constexpr std::uint16_t kDcPulseLength = 0x0982;       // u16
inline constexpr std::uint16_t kDcActivationStatus = 0x0984;  // u8
inline constexpr std::uint16_t kDcSync0Status = 0x098E;       // u8
inline constexpr std::uint16_t kDcSync1Status = 0x098F;       // u8
inline constexpr std::uint16_t kDcStartTime = 0x0990;         // u64 write: start; read: next SYNC0
inline constexpr std::uint16_t kDcNextSync1 = 0x0998;         // u64
inline constexpr std::uint16_t kDcSync0Cycle = 0x09A0;        // u32 ns
inline constexpr std::uint16_t kDcSync1Cycle = 0x09A4;        // u32 ns
inline constexpr std::uint16_t kDcEnd = 0x0A00;

// ---- process RAM ----
inline constexpr std::uint16_t kRamStart = 0x1000;

}  // namespace omnitwin::ethercat::reg
