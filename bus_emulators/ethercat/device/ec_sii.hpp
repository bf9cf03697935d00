// bus_emulators/ethercat/device — the SII EEPROM image of an emulated slave, built from its ESI.
//
// The ESC's EEPROM interface (registers 0x0500–0x050F, A's ec_esc) serves this word image to the
// master, which reads identity, mailbox layout, SyncManagers and PDOs from it exactly as from a
// real slave's EEPROM. Layout (word addresses): 0x00–0x06 ESC configuration area (PDI control,
// PDI configuration, SYNC impulse length, extended PDI configuration, configured station alias),
// 0x07 its checksum (CRC-8, polynomial 0x07, initial 0xFF, over the 14 bytes of words 0–6, in the
// low byte), 0x08/0x0A/0x0C/0x0E vendor ID, product code, revision, serial (32-bit each),
// 0x14–0x17 bootstrap mailbox, 0x18–0x1B standard mailbox (receive = SM0 offset/size, send = SM1
// offset/size), 0x1C mailbox protocols (bit 2 CoE), 0x3E EEPROM size in KiBit − 1, 0x3F version 1,
// then categories from 0x40 (type word, size in words, data): 10 strings, 30 general, 40 FMMU,
// 41 SyncManager, 50 TxPDO, 51 RxPDO, 60 DC (when the ESI has DC op modes), 0xFFFF end.
// Set-up code: allocates, never called on a cyclic path.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "bus_emulators/ethercat/device/ec_esi.hpp"

namespace omnitwin::ethercat {

namespace sii {
inline constexpr std::uint16_t vendor_id = 0x08, product_code = 0x0A, revision = 0x0C, serial = 0x0E,
                               bootstrap_rx_offset = 0x14, bootstrap_rx_size = 0x15,
                               bootstrap_tx_offset = 0x16, bootstrap_tx_size = 0x17,
                               mbx_rx_offset = 0x18, mbx_rx_size = 0x19, mbx_tx_offset = 0x1A,
                               mbx_tx_size = 0x1B, mbx_protocols = 0x1C, size = 0x3E, version = 0x3F,
                               first_category = 0x40;
inline constexpr std::uint16_t cat_strings = 10, cat_datatypes = 20, cat_general = 30, cat_fmmu = 40,
                               cat_syncm = 41, cat_txpdo = 50, cat_rxpdo = 51, cat_dc = 60, cat_end = 0xFFFF;
inline constexpr std::uint16_t proto_aoe = 0x01, proto_eoe = 0x02, proto_coe = 0x04, proto_foe = 0x08,
                               proto_soe = 0x10;
}  // namespace sii

// CRC-8 of the ESC configuration area (poly 0x07, init 0xFF, MSB first, no final XOR). RT-safe.
std::uint8_t sii_crc8(std::span<const std::uint8_t> bytes) noexcept;

// CoE data type code (ETG.1000.6: 0x0001 BOOL … 0x001B UINT64, 0x0030.. BIT1..BIT8) of an ESI
// base type name; 0 when unknown. RT-safe.
std::uint16_t coe_type_code(const std::string& esi_type) noexcept;

// The EEPROM word image of `desc` with the given configured station alias (word 4) and serial
// number (words 0x0E/0x0F), desc.eeprom_bytes / 2 words long (0xFFFF after the end category).
// Throws EsiError when the categories do not fit the EEPROM size.
std::vector<std::uint16_t> build_sii(const DeviceDescription& desc, std::uint16_t alias = 0,
                                     std::uint32_t serial = 0);

}  // namespace omnitwin::ethercat
