// bus_emulators/mechatrolink3 — the standard servo profile's field layout: where each field of
// a command and of its response sits after the 4-byte header (m3_command.hpp). Shared by the
// emulated servo (m3_servo), our C1 master's axes (controller/mechatrolink3) and the tests, so
// that a master written against the public command manual (Yaskawa Σ-7, MECHATROLINK-III
// standard servo profile) reads and writes the same bytes as ours.
//
// The layout is the public one: a servo command is byte 0 CMD, 1 WDT, 2-3 CMD_CTRL, 4-7
// SVCMD_CTRL, 8-11 SVCMD_IO, then five 32-bit fields at 12, 16, 20, 24, 28 whose meaning the
// command gives; a response is RCMD, RWDT, CMD_STAT, 4-7 SVCMD_STAT, 8-11 SVCMD_IO, 12/16
// CPRM_SEL_MON1/2 and 20/24/28 MONITOR1/2/3. The common commands (ID_RD, CONFIG, ALM_RD,
// ALM_CLR, MEM_RD/WR) keep the common format: their fields start at byte 4 and their
// responses carry no SVCMD_STAT or SVCMD_IO. Multi-byte fields are little endian.
// Pure constants: no code, no state.
#pragma once

#include <cstddef>
#include <cstdint>

namespace omnitwin::m3::servo {

// --- Command fields [byte offsets] -------------------------------------------------------
inline constexpr std::size_t kSvcmdCtrl = 4;  // u32, the bits below
inline constexpr std::size_t kSvcmdIoOut = 8;  // u32, output signals (reserved here)
// INTERPOLATE 34h: target position [ref], velocity feed-forward [ref/s], torque feed-forward,
// torque limit [0.1 %] (0: the parameter).
inline constexpr std::size_t kIpTpos = 12, kIpVff = 16, kIpTff = 20, kIpTlim = 28;
// POSING 35h and EX_POSING 39h: target position, speed [ref/s], acceleration and
// deceleration [ref/s²] (0: the parameter), torque limit.
inline constexpr std::size_t kPosTpos = 12, kPosTspd = 16, kPosAccr = 20, kPosDecr = 24, kPosTlim = 28;
// FEED 36h: speed, acceleration, deceleration, torque limit (no position).
inline constexpr std::size_t kFeedTspd = 16, kFeedAccr = 20, kFeedDecr = 24, kFeedTlim = 28;
// ZRET 3Ah: mode (ours: byte 12 the CiA 402 homing method, 0 the parameter), approach speed,
// acceleration, deceleration, torque limit.
inline constexpr std::size_t kZretMode = 12, kZretTspd = 16, kZretAccr = 20, kZretDecr = 24, kZretTlim = 28;
// VELCTRL 3Ch: torque feed-forward, velocity reference [ref/s], acceleration and
// deceleration [ref/s²] (0: the reference takes effect at once), torque limit.
inline constexpr std::size_t kVelTff = 12, kVelVref = 16, kVelAccr = 20, kVelDecr = 24, kVelTlim = 28;
// TRQCTRL 3Dh: velocity limit, torque reference [0.1 %].
inline constexpr std::size_t kTrqVlim = 12, kTrqTqref = 16;
// POS_SET 20h: mode (bit 7 REFE), position.
inline constexpr std::size_t kPosSetMode = 12, kPosSetData = 16;
// SVPRM_RD/WR 40h/41h: NO u16, SIZE, MODE, PARAMETER.
inline constexpr std::size_t kPrmNo = 12, kPrmSize = 14, kPrmMode = 15, kPrmData = 16;
// Common commands, common format: ID_RD 03h (ID_CODE, OFFSET, SIZE u16, the ID from 8),
// CONFIG 04h (CONFIG_MOD), ALM_RD 05h (ALM_RD_MOD u16, ALM_INDEX u16, up to 12 codes u16 from
// 8), ALM_CLR 06h (ALM_CLR_MOD u16).
inline constexpr std::size_t kIdCode = 4, kIdOffset = 5, kIdSize = 6, kIdData = 8;
inline constexpr std::size_t kConfigMode = 4;
inline constexpr std::size_t kAlmMode = 4, kAlmIndex = 6, kAlmData = 8;
inline constexpr std::size_t kAlmCodesMain = 12;  // codes an ALM_RD answer holds (32 bytes)

// --- Response fields --------------------------------------------------------------------
inline constexpr std::size_t kSvcmdStat = 4, kSvcmdIoIn = 8;
inline constexpr std::size_t kCprmMon1 = 12, kCprmMon2 = 16;
inline constexpr std::size_t kMonitor1 = 20, kMonitor2 = 24, kMonitor3 = 28;

// --- SVCMD_CTRL bits ----------------------------------------------------------------------
inline constexpr std::uint32_t kCmdPause = 1u << 0, kCmdCancel = 1u << 1;
inline constexpr unsigned kStopModeShift = 2;  // 2 bits: 0 decelerate to a stop, 1 at once
inline constexpr unsigned kSelMon1Shift = 16, kSelMon2Shift = 20, kSelMon3Shift = 24;  // 4 bits each
// SVCMD_CTRL selecting monitors a, b, c as MONITOR1/2/3.
constexpr std::uint32_t sel_mon(std::uint32_t a, std::uint32_t b = 0, std::uint32_t c = 0) {
  return (a & 0xF) << kSelMon1Shift | (b & 0xF) << kSelMon2Shift | (c & 0xF) << kSelMon3Shift;
}

// --- SVCMD_STAT bits ----------------------------------------------------------------------
inline constexpr std::uint32_t kPauseCmp = 1u << 0, kCancelCmp = 1u << 1, kLCmp1 = 1u << 8, kLCmp2 = 1u << 9,
                               kPosRdy = 1u << 10, kPon = 1u << 11, kMRdy = 1u << 12, kSvOn = 1u << 13;
// bits 16-27: SEL_MON1/2/3 echoed from SVCMD_CTRL.

// --- SVCMD_IO bits of a response (input signals and states) -------------------------------
inline constexpr std::uint32_t kIoDec = 1u << 1, kIoPot = 1u << 2, kIoNot = 1u << 3, kIoBrkOn = 1u << 9,
                               kIoDen = 1u << 12, kIoPset = 1u << 14, kIoZpoint = 1u << 15, kIoZspd = 1u << 19;

// --- Monitor codes (SEL_MON; ours where the profile leaves a code to the vendor) ----------
enum class Monitor : std::uint8_t {
  apos = 0x0, cpos = 0x1, perr = 0x2, lpos1 = 0x3, fspd = 0x5, cspd = 0x6, trq = 0x7, alarm = 0x8, mpos = 0x9,
};

}  // namespace omnitwin::m3::servo
