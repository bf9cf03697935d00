-- tools/wireshark — a Wireshark/tshark dissector for Technosoft TML messages on CAN (seed 003;
-- docs/protocols/tml.md): TMLCAN (29-bit identifiers: opcode, group bit, axis or group ID,
-- HOST bit) and TechCAN (11-bit COB-IDs: group, sync, PVT, TakeData2/PONG, normal, host,
-- TakeData and broadcast ranges, which leave CANopen's free). It is a CAN sub-dissector for
-- the SocketCAN captures the twin writes (bus-can.pcap). Usage:
--   tshark -X lua_script:tools/wireshark/tml.lua -d can.subdissector,tml -r bus-can.pcap
-- A frame outside TechCAN's ranges is shown as "not TML" (on a shared bus: CANopen); a
-- frame of a TML range with a length the protocol does not allow is malformed (expert info),
-- never a Lua error. Field names start with "tml." (filter: tml.opcode == 0xb005).
-- Works with Lua 5.1-5.4 (bit32, Wireshark's bit, or native operators).

local tml = Proto("tml", "Technosoft TML")

local f_proto = ProtoField.string("tml.protocol", "Protocol")
local f_opcode = ProtoField.uint16("tml.opcode", "Operation code", base.HEX)
local f_kind = ProtoField.string("tml.kind", "Instruction")
local f_dest = ProtoField.string("tml.destination", "Destination")
local f_sender = ProtoField.string("tml.sender", "Sender")
local f_address = ProtoField.uint16("tml.address", "Address", base.HEX)
local f_word = ProtoField.uint16("tml.word", "Data word", base.HEX)
tml.fields = { f_proto, f_opcode, f_kind, f_dest, f_sender, f_address, f_word }

local e_length = ProtoExpert.new("tml.length", "Length not allowed by the protocol", expert.group.MALFORMED,
                                 expert.severity.ERROR)
tml.experts = { e_length }

local can_id = Field.new("can.id")
local can_xtd = Field.new("can.flags.xtd")

local function bitops()
  if bit32 then return bit32.band, bit32.rshift, bit32.lshift, bit32.bor end
  if bit then return bit.band, bit.rshift, bit.lshift, bit.bor end
  return load("return function(a, b) return a & b end, function(a, n) return a >> n end, "
              .. "function(a, n) return a << n end, function(a, b) return a | b end")()
end
local band, rshift, lshift, bor = bitops()

-- ---- names -------------------------------------------------------------------------------

local NAMED = {
  [0x0002] = "AXISOFF", [0x0102] = "AXISON", [0x0108] = "UPD", [0x01C4] = "STOP", [0x1C04] = "FAULTR",
  [0x1404] = "SETSYNC", [0x5909] = "bit-set (MODE / TUM / CPA / CPR)", [0x1000] = "SYNC",
  [0x1401] = "set master time", [0xB004] = "GiveMeData 16-bit", [0xB005] = "GiveMeData 32-bit",
  [0xB204] = "GiveMeData2 16-bit", [0xB205] = "GiveMeData2 32-bit", [0xB404] = "TakeData 16-bit",
  [0xB405] = "TakeData 32-bit",
}
local VARIABLES = { [0x025E] = "KPP", [0x022A] = "POSERR", [0x090E] = "SRL", [0x090F] = "SRH", [0x08FC] = "MER",
                    [0x0228] = "APOS", [0x029E] = "CPOS", [0x02A0] = "CSPD", [0x02A2] = "CACC" }

-- The instruction an opcode is, and the address of an assignment.
local function describe(op)
  if NAMED[op] then return NAMED[op], nil end
  local family = band(op, 0xFC00)
  if family == 0x2000 or family == 0x2400 then
    local page = band(op, 0x0200) ~= 0 and 0x0800 or 0x0200
    local addr = page + band(op, 0x01FF)
    local name = VARIABLES[addr] and (" " .. VARIABLES[addr]) or ""
    return string.format("assign %s-bit%s", family == 0x2000 and "16" or "32", name), addr
  end
  if band(op, 0xFE00) == 0xD400 then
    return string.format("TakeData2 %s-bit from axis %d", band(op, 0x0100) ~= 0 and "32" or "16", band(op, 0xFF)), nil
  end
  return "instruction", nil
end

local function words(tree, tvb, from)
  local n = 0
  local i = from
  while i + 1 < tvb:len() do
    tree:add_le(f_word, tvb:range(i, 2))
    n = n + 1
    i = i + 2
  end
  return n
end

local function show_opcode(tree, op, tvb_range)
  local kind, addr = describe(op)
  tree:add_le(f_opcode, tvb_range)
  tree:add(f_kind, kind)
  if addr then tree:add(f_address, addr) end
  return kind
end

-- ---- TMLCAN ------------------------------------------------------------------------------

local function tmlcan(tvb, pinfo, tree, id)
  local op = bor(lshift(band(rshift(id, 22), 0x7F), 9), band(id, 0x1FF))
  local group = band(rshift(id, 21), 1) == 1
  local dest_id = band(rshift(id, 13), 0xFF)
  local host = band(rshift(id, 9), 1) == 1
  local t = tree:add(tml, tvb(), "Technosoft TML (TMLCAN)")
  t:add(f_proto, "TMLCAN (29-bit)")
  local kind, addr = describe(op)
  t:add(f_opcode, op)
  t:add(f_kind, kind)
  if addr then t:add(f_address, addr) end
  local dest = group and string.format("group mask 0x%02X", dest_id) or string.format("axis %d%s", dest_id, host and " (host)" or "")
  t:add(f_dest, dest)
  if tvb:len() % 2 ~= 0 then t:add_proto_expert_info(e_length) end
  words(t, tvb, 0)
  pinfo.cols.info = string.format("TML %s to %s", kind, dest)
end

-- ---- TechCAN -----------------------------------------------------------------------------

local function techcan(tvb, pinfo, tree, id)
  local len = tvb:len()
  local function plain(what, dest)
    local t = tree:add(tml, tvb(), "Technosoft TML (TechCAN " .. what .. ")")
    t:add(f_proto, "TechCAN (11-bit)")
    if len < 2 or len % 2 ~= 0 then
      t:add_proto_expert_info(e_length)
      pinfo.cols.info = "TML " .. what .. " (malformed)"
      return
    end
    local kind = show_opcode(t, tvb:range(0, 2):le_uint(), tvb:range(0, 2))
    t:add(f_dest, dest)
    words(t, tvb, 2)
    pinfo.cols.info = string.format("TML %s to %s", kind, dest)
  end
  if id == 0x020 then
    local t = tree:add(tml, tvb(), "Technosoft TML (TechCAN synchronisation)")
    t:add(f_proto, "TechCAN (11-bit)")
    if len ~= 0 then t:add_proto_expert_info(e_length) end
    pinfo.cols.info = "TML SYNC"
  elseif id == 0x200 then
    plain("broadcast", "all axes")
  elseif id >= 0x001 and id <= 0x01F then
    plain("group", string.format("group mask 0x%02X", id))
  elseif id >= 0x121 and id <= 0x13F then
    plain("normal", string.format("axis %d", id - 0x120))
  elseif id >= 0x141 and id <= 0x15F then
    plain("host", string.format("axis %d (host)", id - 0x140))
  elseif id >= 0x041 and id <= 0x05F then
    local t = tree:add(tml, tvb(), "Technosoft TML (TechCAN PVT point)")
    t:add(f_proto, "TechCAN (11-bit)")
    if len ~= 8 then t:add_proto_expert_info(e_length) end
    t:add(f_dest, string.format("axis %d", id - 0x40))
    pinfo.cols.info = string.format("TML PVT point to axis %d", id - 0x40)
  elseif id >= 0x101 and id <= 0x11F then
    local t = tree:add(tml, tvb(), "Technosoft TML (TechCAN TakeData2 / PONG)")
    t:add(f_proto, "TechCAN (11-bit)")
    if len < 1 then
      t:add_proto_expert_info(e_length)
      return
    end
    local b0 = tvb:range(0, 1):uint()
    local pong = band(b0, 0x40) ~= 0
    t:add(f_sender, string.format("axis %d", id - 0x100))
    if not pong and len >= 3 then t:add_le(f_address, tvb:range(1, 2)) end
    pinfo.cols.info = string.format("TML %s from axis %d", pong and "PONG" or "TakeData2", id - 0x100)
  elseif id >= 0x161 and id <= 0x17F then
    local t = tree:add(tml, tvb(), "Technosoft TML (TechCAN TakeData)")
    t:add(f_proto, "TechCAN (11-bit)")
    if len < 4 or len % 2 ~= 0 then t:add_proto_expert_info(e_length) end
    t:add(f_sender, string.format("axis %d", id - 0x160))
    if len >= 4 then t:add_le(f_address, tvb:range(2, 2)) end
    pinfo.cols.info = string.format("TML TakeData from axis %d", id - 0x160)
  else
    pinfo.cols.info = string.format("not TML (COB-ID 0x%03X)", id)
  end
end

function tml.dissector(tvb, pinfo, tree)
  local id_field, xtd_field = can_id(), can_xtd()
  if not id_field then return 0 end
  pinfo.cols.protocol = "TML"
  local id = id_field.value
  if xtd_field and xtd_field.value then tmlcan(tvb, pinfo, tree, id) else techcan(tvb, pinfo, tree, id) end
  return tvb:len()
end

DissectorTable.get("can.subdissector"):add_for_decode_as(tml)
