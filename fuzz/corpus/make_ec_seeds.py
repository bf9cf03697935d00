#!/usr/bin/env python3
"""Writes the seed inputs of the EtherCAT fuzz targets (fuzz/corpus/ec_datagram, ec_mailbox,
ec_esi). Re-run after changing it: python3 fuzz/corpus/make_ec_seeds.py"""
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))

# ---- ec_datagram: EtherCAT PDUs (header + datagrams), as the set-up master addresses the line:
# stations 0x1001.., FMMU0 outputs at logical 0x00010000 + 0x40·p, FMMU1 inputs at 0x00020000 + 0x40·p.
NOP, APRD, APWR, APRW, FPRD, FPWR, FPRW, BRD, BWR, BRW, LRD, LWR, LRW, ARMW, FRMW = range(15)


def dgram(cmd, adp, ado, data, more):
    n = len(data)
    return struct.pack('<BBHHHH', cmd, 0, adp & 0xFFFF, ado & 0xFFFF, n | (0x8000 if more else 0), 0) + bytes(data) + b'\0\0'


def pdu(*dgs):
    body = b''.join(dgram(c, adp, ado, d, i + 1 < len(dgs)) for i, (c, adp, ado, d) in enumerate(dgs))
    return struct.pack('<H', len(body) | 0x1000) + body


def u16(v): return struct.pack('<H', v)
def u32(v): return struct.pack('<I', v)
def u64(v): return struct.pack('<Q', v)


def sm(start, length, control, enable=1):
    return u16(start) + u16(length) + bytes([control, 0, enable, 0])


def fmmu(log, length, phys, typ):
    return u32(log) + u16(length) + bytes([0, 7]) + u16(phys) + bytes([0, typ, 1, 0, 0, 0, 0])


datagram_seeds = {
    'brd_type': pdu((BRD, 0, 0x0000, b'\0' * 10)),
    'aprd_al_status': pdu((APRD, 0, 0x0130, b'\0' * 6)),
    'apwr_station': pdu((APWR, 0, 0x0010, u16(0x1001)), (APWR, 0xFFFF, 0x0010, u16(0x1002)),
                        (APWR, 0xFFFE, 0x0010, u16(0x1003))),
    'fprd_dl_status': pdu((FPRD, 0x1001, 0x0110, b'\0' * 2), (FPRD, 0x1002, 0x0100, b'\0' * 4)),
    'mailbox_sms': pdu((FPWR, 0x1001, 0x0800, sm(0x1000, 128, 0x26) + sm(0x1080, 128, 0x22))),
    'al_preop': pdu((FPWR, 0x1001, 0x0120, u16(0x0012)), (FPRD, 0x1001, 0x0130, b'\0' * 6)),
    'al_safeop': pdu((BWR, 0, 0x0120, u16(0x0004)), (BRD, 0, 0x0130, b'\0' * 2)),
    'al_op': pdu((BWR, 0, 0x0120, u16(0x0008)), (BRD, 0, 0x0134, b'\0' * 2)),
    'pd_sms_fmmus': pdu((FPWR, 0x1001, 0x0810, sm(0x1100, 16, 0x64) + sm(0x1180, 24, 0x20)),
                        (FPWR, 0x1001, 0x0600, fmmu(0x00010000, 16, 0x1100, 2) + fmmu(0x00020000, 24, 0x1180, 1))),
    'lrw_image': pdu((LRW, 0x0000, 0x0001, b'\x0f\x00' + b'\0' * 14 + b'\x0f\x00' + b'\0' * 110),
                     (LRD, 0x0000, 0x0002, b'\0' * 160)),
    'lwr_outputs': pdu((LWR, 0x0040, 0x0001, b'\x06\x00\x09' + b'\0' * 13)),
    'eeprom_read': pdu((FPWR, 0x1001, 0x0502, u16(0x0100) + u32(0x0008)), (FPRD, 0x1001, 0x0502, b'\0' * 14)),
    'eeprom_reload': pdu((BWR, 0, 0x0500, b'\0'), (BWR, 0, 0x0502, u16(0x0400))),
    'dc_latch': pdu((BWR, 0, 0x0900, u32(0)), (FPRD, 0x1001, 0x0900, b'\0' * 16), (FPRD, 0x1002, 0x0918, b'\0' * 8)),
    'dc_sync': pdu((FPWR, 0x1001, 0x0920, u64(1000000)), (ARMW, 0, 0x0910, b'\0' * 8), (FRMW, 0x1001, 0x0910, b'\0' * 8)),
    'dc_sync0': pdu((FPWR, 0x1001, 0x09A0, u32(1000000)), (FPWR, 0x1001, 0x0990, u64(5000000)),
                    (FPWR, 0x1001, 0x0980, u16(0x0300)), (FPRD, 0x1001, 0x098E, b'\0' * 10)),
    'mailbox_write': pdu((FPWR, 0x1001, 0x1000,
                          u16(10) + u16(0) + bytes([0, 0x13]) + u16(0x2000) + bytes([0x40]) + u16(0x1000) + bytes([0]) + b'\0' * 4
                          + b'\0' * 112)),
    'mailbox_read': pdu((FPRD, 0x1001, 0x080D, b'\0'), (FPRD, 0x1001, 0x1080, b'\0' * 128)),
    'watchdog': pdu((BWR, 0, 0x0400, u16(2)), (BWR, 0, 0x0420, u16(10)), (BRD, 0, 0x0440, b'\0' * 4)),
    'nop_undefined': pdu((NOP, 0, 0, b'\x55' * 4), (0x20, 0, 0, b'\xaa' * 4)),
    'aprw_brw': pdu((APRW, 0xFFFF, 0x0200, u16(0xFFFF)), (BRW, 0, 0x0300, b'\0' * 8)),
}

# ---- ec_mailbox: SM0 mailboxes (128 bytes each; an input may hold several) -----------------
counter = [0]


def mbx(payload, typ=3):
    counter[0] = counter[0] % 7 + 1
    m = u16(len(payload)) + u16(0) + bytes([0, typ | counter[0] << 4]) + payload
    return m + b'\0' * (128 - len(m))


def sdo(cmd, index, sub, data=b'\0' * 4):
    return u16(0x2000) + bytes([cmd]) + u16(index) + bytes([sub]) + data


def info(opcode, data):
    return u16(0x8000) + bytes([opcode, 0]) + u16(0) + data


mailbox_seeds = {
    'upload_1000': mbx(sdo(0x40, 0x1000, 0)),
    'upload_1018_4': mbx(sdo(0x40, 0x1018, 4)),
    'upload_1008_string': mbx(sdo(0x40, 0x1008, 0)),
    'upload_1c12_ca': mbx(sdo(0x50, 0x1C12, 0)),
    'upload_1600_ca': mbx(sdo(0x50, 0x1600, 0)),
    'download_6060': mbx(sdo(0x2F, 0x6060, 0, b'\x08\0\0\0')),
    'download_607a': mbx(sdo(0x23, 0x607A, 0, u32(123456))),
    'download_1c12_ca': mbx(sdo(0x31, 0x1C12, 0, u32(4)) + b'\x01\x00\x00\x16'),
    'download_1600_clear_map': mbx(sdo(0x2F, 0x1600, 0, b'\0\0\0\0')) + mbx(sdo(0x23, 0x1600, 1, u32(0x60400010)))
    + mbx(sdo(0x2F, 0x1600, 0, b'\x01\0\0\0')),
    'segmented_download': mbx(sdo(0x31, 0x1600, 0, u32(150)) + b'\x01' * 100)
    + mbx(u16(0x2000) + bytes([0x00]) + b'\x02' * 40)
    + mbx(u16(0x2000) + bytes([0x11]) + b'\x03' * 10),
    'segmented_download_1c12': mbx(sdo(0x31, 0x1C12, 0, u32(4)) + b'\x01\x00')
    + mbx(u16(0x2000) + bytes([0x09]) + b'\x00\x16' + b'\0' * 5),
    'segmented_upload': mbx(sdo(0x40, 0x1008, 0)) + mbx(u16(0x2000) + bytes([0x60]) + b'\0' * 7)
    + mbx(u16(0x2000) + bytes([0x70]) + b'\0' * 7),
    'info_od_list': mbx(info(0x01, u16(0x0001))) + mbx(info(0x01, u16(0x0002))) + mbx(info(0x01, u16(0x0000))),
    'info_object': mbx(info(0x03, u16(0x6040))) + mbx(info(0x03, u16(0x1018))),
    'info_entry': mbx(info(0x05, u16(0x6040) + bytes([0, 0x7F]))) + mbx(info(0x05, u16(0x1600) + bytes([1, 0x0F]))),
    'eoe_unsupported': mbx(b'\0' * 20, typ=2),
    'short_coe': mbx(b'\x00', typ=3),
    'abort_request': mbx(sdo(0x80, 0x6040, 0, u32(0x05040000))),
}

# ---- ec_esi: a small complete ESI (the shipped ones are seeded from models/ethercat) ----------
small_esi = b'''<?xml version="1.0"?>
<EtherCATInfo>
  <Vendor><Id>#x00000F1C</Id><Name>fuzz</Name></Vendor>
  <Descriptions>
    <Groups><Group><Type>Drives</Type><Name>Drives</Name></Group></Groups>
    <Devices>
      <Device Physics="YY">
        <Type ProductCode="#x1" RevisionNo="#x10000">small</Type>
        <Name>small drive</Name>
        <GroupType>Drives</GroupType>
        <Fmmu>Outputs</Fmmu><Fmmu>Inputs</Fmmu><Fmmu>MBoxState</Fmmu>
        <Sm DefaultSize="128" StartAddress="#x1000" ControlByte="#x26" Enable="1">MBoxOut</Sm>
        <Sm DefaultSize="128" StartAddress="#x1080" ControlByte="#x22" Enable="1">MBoxIn</Sm>
        <Sm StartAddress="#x1100" ControlByte="#x64" Enable="1">Outputs</Sm>
        <Sm StartAddress="#x1180" ControlByte="#x20" Enable="1">Inputs</Sm>
        <RxPdo Fixed="1" Sm="2"><Index>#x1600</Index><Name>Rx</Name>
          <Entry><Index>#x6040</Index><SubIndex>0</SubIndex><BitLen>16</BitLen><Name>Controlword</Name><DataType>UINT</DataType></Entry>
        </RxPdo>
        <TxPdo Fixed="1" Sm="3"><Index>#x1A00</Index><Name>Tx</Name>
          <Entry><Index>#x6041</Index><SubIndex>0</SubIndex><BitLen>16</BitLen><Name>Statusword</Name><DataType>UINT</DataType></Entry>
        </TxPdo>
        <Mailbox DataLinkLayer="1"><CoE SdoInfo="1" CompleteAccess="1" PdoAssign="1" PdoConfig="1"/></Mailbox>
        <Dc><OpMode><Name>DC</Name><Desc>DC-Synchron</Desc><AssignActivate>#x0300</AssignActivate><CycleTimeSync0>0</CycleTimeSync0></OpMode></Dc>
        <Eeprom><ByteSize>2048</ByteSize><ConfigData>080E00CC0100</ConfigData></Eeprom>
        <Profile><ProfileNo>402</ProfileNo><ChannelCount>1</ChannelCount>
          <Dictionary>
            <DataTypes>
              <DataType><Name>UINT</Name><BitSize>16</BitSize></DataType>
              <DataType><Name>DT1C12</Name><BitSize>32</BitSize>
                <SubItem><SubIdx>0</SubIdx><Name>n</Name><Type>USINT</Type><BitSize>8</BitSize><BitOffs>0</BitOffs></SubItem>
                <SubItem><SubIdx>1</SubIdx><Name>e</Name><Type>UINT</Type><BitSize>16</BitSize><BitOffs>16</BitOffs></SubItem>
              </DataType>
              <DataType><Name>ARR</Name><BaseType>UINT</BaseType><BitSize>32</BitSize><ArrayInfo><LBound>1</LBound><Elements>2</Elements></ArrayInfo></DataType>
            </DataTypes>
            <Objects>
              <Object><Index>#x6040</Index><Name>Controlword</Name><Type>UINT</Type><BitSize>16</BitSize>
                <Info><DefaultData>0000</DefaultData></Info><Flags><Access>rw</Access><PdoMapping>R</PdoMapping></Flags></Object>
              <Object><Index>#x6041</Index><Name>Statusword</Name><Type>UINT</Type><BitSize>16</BitSize>
                <Flags><Access>ro</Access><PdoMapping>T</PdoMapping></Flags></Object>
              <Object><Index>#x1C12</Index><Name>RxPDO assign</Name><Type>DT1C12</Type><BitSize>32</BitSize>
                <Info><SubItem><Name>n</Name><Info><DefaultData>01</DefaultData></Info></SubItem>
                <SubItem><Name>e</Name><Info><DefaultData>0016</DefaultData></Info></SubItem></Info>
                <Flags><Access WriteRestrictions="PreOP">rw</Access></Flags></Object>
            </Objects>
          </Dictionary>
        </Profile>
      </Device>
    </Devices>
  </Descriptions>
</EtherCATInfo>
'''

esi_seeds = {
    'small': small_esi,
    'no_vendor': b'<EtherCATInfo><Descriptions><Devices><Device/></Devices></Descriptions></EtherCATInfo>',
    'bad_number': small_esi.replace(b'#x00000F1C', b'#xZZ'),
}

for sub, seeds in (('ec_datagram', datagram_seeds), ('ec_mailbox', mailbox_seeds), ('ec_esi', esi_seeds)):
    d = os.path.join(HERE, sub)
    os.makedirs(d, exist_ok=True)
    for name, data in seeds.items():
        with open(os.path.join(d, name), 'wb') as f:
            f.write(data)
