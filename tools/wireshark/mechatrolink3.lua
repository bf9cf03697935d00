-- tools/wireshark — a Wireshark/tshark dissector for MECHATROLINK-III frames as the twin
-- carries them (docs/protocols/mechatrolink3.md): in Ethernet frames with EtherType 0x88B5
-- (the captures bus_emulators/mechatrolink3/m3_pcap writes) and in UDP datagrams on port
-- 34997. Usage:  tshark -X lua_script:tools/wireshark/mechatrolink3.lua -r bus-m3.pcap
--
-- The frame layout, addresses and frame-type codes are ours (the M-III specification is not
-- public); the application header of CMD/RSP/EVT_CMD/EVT_RSP information fields and the
-- command codes follow the public standard servo profile. Like the receiving station, the
-- dissector checks the FCS (CRC-32 IEEE 802.3, computed here) and the data length, and shows
-- a bad frame as bad (expert info), never as a Lua error: every range it reads is checked
-- against the bytes captured first. Field names start with "m3." (filter: m3.fcs.status == 0).
-- Works with Lua 5.1-5.4 (bit32, Wireshark's bit, or native operators).

local m3 = Proto("m3", "MECHATROLINK-III")

local HEADER, FCS_SIZE, MAX_DATA, SUB_OFFSET = 5, 4, 64, 32

-- ---- bit operations and CRC-32 -----------------------------------------------------------

local function bitops()
  if bit32 then return bit32.bxor, bit32.band, bit32.rshift end
  if bit then return bit.bxor, bit.band, bit.rshift end
  return load("return function(a, b) return a ~ b end, function(a, b) return a & b end, "
              .. "function(a, n) return a >> n end")()
end
local bxor, band, rshift = bitops()

local function unsigned32(x)
  if x < 0 then return x + 4294967296 end
  return x
end

local function crc_table()
  local t = {}
  for i = 0, 255 do
    local c = i
    for _ = 1, 8 do
      if band(c, 1) ~= 0 then c = bxor(0xEDB88320, rshift(c, 1)) else c = rshift(c, 1) end
    end
    t[i] = c
  end
  return t
end
local CRC_TABLE = crc_table()

-- CRC-32 (IEEE 802.3, zlib's crc32) of the first len (>= 1) bytes of tvb.
local function crc32(tvb, len)
  local bytes = tvb:range(0, len):bytes()
  local c = 0xFFFFFFFF
  for i = 0, len - 1 do
    c = bxor(CRC_TABLE[band(bxor(c, bytes:get_index(i)), 0xFF)], rshift(c, 8))
  end
  return unsigned32(band(bxor(c, 0xFFFFFFFF), 0xFFFFFFFF))
end

-- ---- names -------------------------------------------------------------------------------

local function address_names()
  local t = { [0x00] = "reserved", [0x01] = "C1 master", [0x02] = "C2 master", [0xFF] = "broadcast" }
  for a = 0x03, 0xEF do t[a] = "slave " .. (a - 2) end
  for a = 0xF0, 0xFE do t[a] = "reserved" end
  return t
end
local ADDRESSES = address_names()

local TYPES = {
  [0x01] = "SYNC", [0x02] = "CMD", [0x03] = "RSP", [0x04] = "EVT_CMD", [0x05] = "EVT_RSP",
  [0x10] = "DETECT", [0x11] = "DETECT_RPL", [0x12] = "DLY_REQ", [0x13] = "DLY_RPL",
  [0x14] = "CYC_NOTIFY", [0x15] = "COMM_START",
}

local CYCLIC = { [8] = true, [16] = true, [32] = true, [48] = true, [64] = true }
local LENGTHS = {
  [0x01] = { [8] = true }, [0x02] = CYCLIC, [0x03] = CYCLIC, [0x04] = { [64] = true },
  [0x05] = { [64] = true }, [0x10] = { [0] = true }, [0x11] = { [8] = true },
  [0x12] = { [0] = true }, [0x13] = { [0] = true }, [0x14] = { [16] = true },
  [0x15] = { [8] = true },
}

-- Frame types whose information field is a command (true) or a response (false).
local APPLICATION = { [0x02] = true, [0x03] = false, [0x04] = true, [0x05] = false }

local COMMANDS = {
  [0x00] = "NOP", [0x03] = "ID_RD", [0x04] = "CONFIG", [0x05] = "ALM_RD", [0x06] = "ALM_CLR",
  [0x0D] = "SYNC_SET", [0x0E] = "CONNECT", [0x0F] = "DISCONNECT", [0x1D] = "MEM_RD",
  [0x1E] = "MEM_WR", [0x20] = "POS_SET", [0x21] = "BRK_ON", [0x22] = "BRK_OFF",
  [0x23] = "SENS_ON", [0x24] = "SENS_OFF", [0x30] = "SMON", [0x31] = "SV_ON", [0x32] = "SV_OFF",
  [0x34] = "INTERPOLATE", [0x35] = "POSING", [0x36] = "FEED", [0x39] = "EX_POSING",
  [0x3A] = "ZRET", [0x3C] = "VELCTRL", [0x3D] = "TRQCTRL", [0x40] = "SVPRM_RD",
  [0x41] = "SVPRM_WR",
}

-- CMD_STAT's CMD_ALM and COMM_ALM codes (bus_emulators/mechatrolink3/m3_command.hpp).
local CMD_ALARMS = {
  [0x0] = "normal", [0x1] = "invalid data (warning)", [0x8] = "unsupported command",
  [0x9] = "invalid data", [0xA] = "execution condition error", [0xB] = "subcommand combination error",
  [0xC] = "phase error",
}
local COMM_ALARMS = {
  [0x0] = "normal", [0x1] = "FCS error (warning)", [0x2] = "command missing (warning)",
  [0x3] = "sync missing (warning)", [0x8] = "FCS error", [0x9] = "command missing",
  [0xA] = "sync missing", [0xB] = "sync interval error", [0xC] = "WDT error",
}

local function command_name(code)
  return COMMANDS[code] or string.format("unknown command 0x%02x", code)
end

-- ---- fields and expert infos -------------------------------------------------------------

local f = {
  dst = ProtoField.uint8("m3.dst", "Destination address", base.HEX, ADDRESSES),
  src = ProtoField.uint8("m3.src", "Source address", base.HEX, ADDRESSES),
  ctrl = ProtoField.uint8("m3.ctrl", "Message control", base.HEX),
  seq = ProtoField.uint8("m3.ctrl.seq", "Sequence", base.DEC, nil, 0x0F),
  retry = ProtoField.bool("m3.ctrl.retry", "Retry", 8, nil, 0x10),
  reserved = ProtoField.uint8("m3.ctrl.reserved", "Reserved", base.HEX, nil, 0xE0),
  type = ProtoField.uint8("m3.type", "Frame type", base.HEX, TYPES),
  len = ProtoField.uint8("m3.len", "Data length", base.DEC),
  data = ProtoField.bytes("m3.data", "Information field"),
  fcs = ProtoField.uint32("m3.fcs", "FCS", base.HEX),
  fcs_calc = ProtoField.uint32("m3.fcs.computed", "Computed FCS", base.HEX),
  fcs_status = ProtoField.uint8("m3.fcs.status", "FCS status", base.DEC,
                                { [0] = "Bad", [1] = "Good", [2] = "Unverified" }),
  cmd = ProtoField.uint8("m3.cmd", "Command code", base.HEX, COMMANDS),
  wdt = ProtoField.uint8("m3.wdt", "WDT", base.HEX),
  cmd_ctrl = ProtoField.uint16("m3.cmd_ctrl", "CMD_CTRL", base.HEX),
  ctrl_alm_clr = ProtoField.bool("m3.cmd_ctrl.alm_clr", "ALM_CLR", 16, nil, 0x0008),
  ctrl_cmd_id = ProtoField.uint16("m3.cmd_ctrl.cmd_id", "CMD_ID", base.DEC, nil, 0x00C0),
  cmd_data = ProtoField.bytes("m3.cmd_data", "Command data"),
  rcmd = ProtoField.uint8("m3.rcmd", "RCMD (command code echoed)", base.HEX, COMMANDS),
  rwdt = ProtoField.uint8("m3.rwdt", "RWDT", base.HEX),
  cmd_stat = ProtoField.uint16("m3.cmd_stat", "CMD_STAT", base.HEX),
  stat_d_alm = ProtoField.bool("m3.cmd_stat.d_alm", "D_ALM", 16, nil, 0x0001),
  stat_d_war = ProtoField.bool("m3.cmd_stat.d_war", "D_WAR", 16, nil, 0x0002),
  stat_cmdrdy = ProtoField.bool("m3.cmd_stat.cmdrdy", "CMDRDY", 16, nil, 0x0004),
  stat_alm_clr_cmp = ProtoField.bool("m3.cmd_stat.alm_clr_cmp", "ALM_CLR_CMP", 16, nil, 0x0008),
  stat_rcmd_id = ProtoField.uint16("m3.cmd_stat.rcmd_id", "RCMD_ID", base.DEC, nil, 0x00C0),
  stat_cmd_alm = ProtoField.uint16("m3.cmd_stat.cmd_alm", "CMD_ALM", base.HEX, CMD_ALARMS, 0x0F00),
  stat_comm_alm = ProtoField.uint16("m3.cmd_stat.comm_alm", "COMM_ALM", base.HEX, COMM_ALARMS, 0xF000),
  rsp_data = ProtoField.bytes("m3.rsp_data", "Response data"),
  sub_cmd = ProtoField.uint8("m3.sub_cmd", "SUB_CMD", base.HEX, COMMANDS),
  sub_ctrl = ProtoField.uint24("m3.sub_ctrl", "SUB_CTRL", base.HEX),
  sub_rcmd = ProtoField.uint8("m3.sub_rcmd", "SUB_RCMD (subcommand echoed)", base.HEX, COMMANDS),
  sub_stat = ProtoField.uint24("m3.sub_stat", "SUB_STAT", base.HEX),
  sub_data = ProtoField.bytes("m3.sub_data", "Subcommand data"),
}
m3.fields = { f.dst, f.src, f.ctrl, f.seq, f.retry, f.reserved, f.type, f.len, f.data, f.fcs,
              f.fcs_calc, f.fcs_status, f.cmd, f.wdt, f.cmd_ctrl, f.cmd_data, f.rcmd, f.rwdt,
              f.cmd_stat, f.rsp_data, f.ctrl_alm_clr, f.ctrl_cmd_id, f.stat_d_alm, f.stat_d_war,
              f.stat_cmdrdy, f.stat_alm_clr_cmp, f.stat_rcmd_id, f.stat_cmd_alm, f.stat_comm_alm,
              f.sub_cmd, f.sub_ctrl, f.sub_rcmd, f.sub_stat, f.sub_data }

local e = {
  bad_fcs = ProtoExpert.new("m3.fcs.bad", "Bad FCS", expert.group.CHECKSUM, expert.severity.ERROR),
  truncated = ProtoExpert.new("m3.truncated", "Frame truncated", expert.group.PROTOCOL,
                              expert.severity.ERROR),
  bad_length = ProtoExpert.new("m3.len.bad", "Data length not allowed", expert.group.PROTOCOL,
                               expert.severity.ERROR),
  unknown_type = ProtoExpert.new("m3.type.unknown", "Unknown frame type", expert.group.PROTOCOL,
                                 expert.severity.ERROR),
  bad_address = ProtoExpert.new("m3.addr.bad", "Invalid station address", expert.group.PROTOCOL,
                                expert.severity.ERROR),
  reserved_bits = ProtoExpert.new("m3.ctrl.reserved_set", "Reserved message-control bits set",
                                  expert.group.PROTOCOL, expert.severity.ERROR),
}
m3.experts = { e.bad_fcs, e.truncated, e.bad_length, e.unknown_type, e.bad_address, e.reserved_bits }

-- ---- dissection --------------------------------------------------------------------------

local function is_station(a) return a >= 0x01 and a <= 0xEF end

-- The header fields present in the first avail bytes; returns the frame type item (or nil).
local function add_header(tvb, tree, avail)
  local fields = { f.dst, f.src, f.ctrl, f.type, f.len }
  local items = {}
  for i = 1, math.min(avail, HEADER) do items[i] = tree:add(fields[i], tvb:range(i - 1, 1)) end
  if items[3] then
    items[3]:add(f.seq, tvb:range(2, 1))
    items[3]:add(f.retry, tvb:range(2, 1))
    items[3]:add(f.reserved, tvb:range(2, 1))
  end
  return items
end

-- Expert infos for the header's addresses, control bits, type and data length.
local function check_header(tvb, items, notes)
  local dst, src, ctrl = tvb:range(0, 1):uint(), tvb:range(1, 1):uint(), tvb:range(2, 1):uint()
  local ftype, n = tvb:range(3, 1):uint(), tvb:range(4, 1):uint()
  if not (is_station(dst) or dst == 0xFF) then items[1]:add_proto_expert_info(e.bad_address) end
  if not is_station(src) then items[2]:add_proto_expert_info(e.bad_address) end
  if not (is_station(dst) or dst == 0xFF) or not is_station(src) then table.insert(notes, "bad address") end
  if band(ctrl, 0xE0) ~= 0 then
    items[3]:add_proto_expert_info(e.reserved_bits)
    table.insert(notes, "reserved bits set")
  end
  if not TYPES[ftype] then
    items[4]:add_proto_expert_info(e.unknown_type)
    table.insert(notes, "unknown type")
  elseif not LENGTHS[ftype][n] then
    local why = string.format("Data length %d not allowed for %s", n, TYPES[ftype])
    items[5]:add_proto_expert_info(e.bad_length, why)
    table.insert(notes, "bad data length")
  end
end

-- The FCS after n data bytes, checked; appends "bad FCS" to notes when it does not match.
local function add_fcs(tvb, tree, n, notes)
  local stored = tvb:range(HEADER + n, FCS_SIZE):le_uint()
  local computed = crc32(tvb, HEADER + n)
  local item = tree:add_le(f.fcs, tvb:range(HEADER + n, FCS_SIZE))
  item:add(f.fcs_calc, computed):set_generated()
  item:add(f.fcs_status, stored == computed and 1 or 0):set_generated()
  if stored ~= computed then
    item:add_proto_expert_info(e.bad_fcs, string.format("Bad FCS 0x%08x, computed 0x%08x", stored, computed))
    table.insert(notes, "bad FCS")
  end
end

-- Bytes 32..47 of a 48-byte command or response: the subcommand region.
local function add_subcommand(r, tree, is_cmd)
  local sub = tree:add(r, "Subcommand")
  sub:add(is_cmd and f.sub_cmd or f.sub_rcmd, r:range(0, 1))
  sub:add_le(is_cmd and f.sub_ctrl or f.sub_stat, r:range(1, 3))
  sub:add(f.sub_data, r:range(4))
  return command_name(r:range(0, 1):uint())
end

-- CMD_CTRL (command) or CMD_STAT (response) at r, little endian, with its bit fields.
local function add_ctrl_stat(r, tree, is_cmd)
  local item = tree:add_le(is_cmd and f.cmd_ctrl or f.cmd_stat, r)
  local bits = is_cmd and { f.ctrl_alm_clr, f.ctrl_cmd_id }
      or { f.stat_d_alm, f.stat_d_war, f.stat_cmdrdy, f.stat_alm_clr_cmp, f.stat_rcmd_id,
           f.stat_cmd_alm, f.stat_comm_alm }
  for _, field in ipairs(bits) do item:add_le(field, r) end
end

-- The application header of a command or response of n >= 4 bytes; returns the Info text.
local function add_application(r, tree, n, is_cmd)
  local app = tree:add(r, is_cmd and "Command" or "Response")
  app:add(is_cmd and f.cmd or f.rcmd, r:range(0, 1))
  app:add(is_cmd and f.wdt or f.rwdt, r:range(1, 1))
  add_ctrl_stat(r:range(2, 2), app, is_cmd)
  local main_end = (n == 48) and SUB_OFFSET or n
  if main_end > 4 then app:add(is_cmd and f.cmd_data or f.rsp_data, r:range(4, main_end - 4)) end
  local info = command_name(r:range(0, 1):uint())
  if n == 48 then info = info .. " + " .. add_subcommand(r:range(SUB_OFFSET, 16), app, is_cmd) end
  return info
end

-- The information field (n bytes, all captured); returns the Info text of its command.
local function add_data(tvb, tree, ftype, n)
  if n == 0 then return nil end
  local r = tvb:range(HEADER, n)
  local item = tree:add(f.data, r)
  local is_cmd = APPLICATION[ftype]
  if is_cmd == nil or n < 4 then return nil end
  return add_application(r, item, n, is_cmd)
end

local function info_text(tvb, avail, app, notes)
  if avail < HEADER then return "truncated frame" end
  local ftype = tvb:range(3, 1):uint()
  local s = string.format("%s %s → %s seq %d", TYPES[ftype] or string.format("type 0x%02x", ftype),
                          ADDRESSES[tvb:range(1, 1):uint()], ADDRESSES[tvb:range(0, 1):uint()],
                          band(tvb:range(2, 1):uint(), 0x0F))
  if band(tvb:range(2, 1):uint(), 0x10) ~= 0 then s = s .. " retry" end
  if app then s = s .. " " .. app end
  if #notes > 0 then s = s .. " [" .. table.concat(notes, ", ") .. "]" end
  return s
end

-- Data length n says the frame is `size` bytes; fewer were captured (or n is over 64).
local function add_broken(tvb, tree, avail, n, notes)
  local size = HEADER + n + FCS_SIZE
  if avail > HEADER then tree:add(f.data, tvb:range(HEADER, math.min(avail, HEADER + n) - HEADER)) end
  if n > MAX_DATA then
    tree:add_proto_expert_info(e.bad_length, string.format("Data length %d over %d", n, MAX_DATA))
    table.insert(notes, "bad data length")
  else
    tree:add_proto_expert_info(e.truncated, string.format("%d of %d bytes", avail, size))
    table.insert(notes, "truncated")
  end
end

function m3.dissector(tvb, pinfo, tree)
  local avail = tvb:len()
  if avail == 0 then return 0 end
  pinfo.cols.protocol:set("M-III")
  local n = avail >= HEADER and tvb:range(4, 1):uint() or MAX_DATA + 1
  local size = HEADER + n + FCS_SIZE
  local complete = n <= MAX_DATA and avail >= size
  local used = complete and size or avail
  local root = tree:add(m3, tvb:range(0, used))
  local items, notes, app = add_header(tvb, root, avail), {}, nil
  if avail < HEADER then
    root:add_proto_expert_info(e.truncated, string.format("%d bytes, a header is %d", avail, HEADER))
  elseif not complete then
    add_broken(tvb, root, avail, n, notes)
  else
    check_header(tvb, items, notes)
    app = add_data(tvb, root, tvb:range(3, 1):uint(), n)
    add_fcs(tvb, root, n, notes)
  end
  pinfo.cols.info:set(info_text(tvb, avail, app, notes))
  return used
end

DissectorTable.get("ethertype"):add(0x88B5, m3)
DissectorTable.get("udp.port"):add(34997, m3)
