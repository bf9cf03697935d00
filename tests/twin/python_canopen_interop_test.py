#!/usr/bin/python3
# Tests that a python-can script (python3-can from Debian, interface udp_multicast) joins the
# UDP bus of `omnitwin run --bus canopen` (our CANopen master and the twin's four CiA 402
# drives as two processes, realtime clock) and talks CANopen to a drive by hand: it sees every
# drive's heartbeat (0x701..0x704) and synchronous TPDO1 (0x181..0x184) and the master's SYNC
# and RPDOs, reads node 2's identity 0x1018:1..4 with hand-written expedited SDO uploads (the
# values must be the EDS's), reads the device name 0x1008 with a hand-written segmented upload
# (toggle bit alternating), and gets abort 0x06020000 for an object that does not exist.
#
# Usage: python_canopen_interop_test.py OMNITWIN SCENARIO EDS PORT
import os
import re
import subprocess
import sys
import tempfile
import time

import can

GROUP = "239.74.163.2"
NODE = 2


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


def eds_value(eds, section, key):
    """A key of the EDS (the file the drives are built from), as the text after '='."""
    text = open(eds, encoding="latin-1").read()
    m = re.search(r"^\[" + section + r"\]\s*$(.*?)^\[", text, re.M | re.S | re.I)
    if not m:
        fail(f"{eds}: no [{section}]")
    for line in m.group(1).splitlines():
        k, _, v = line.partition("=")
        if k.strip().lower() == key.lower():
            return v.strip()
    fail(f"{eds}: [{section}] has no {key}")


def receive_for(bus, seconds, until=None):
    frames = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        m = bus.recv(timeout=0.05)
        if m is not None:
            frames.append(m)
            if until and until(frames):
                break
    return frames


def sdo(bus, payload):
    """One SDO request to NODE; the server's answer (0x580 + NODE) as 8 bytes."""
    bus.send(can.Message(arbitration_id=0x600 + NODE, data=bytes(payload), is_extended_id=False))
    answer = receive_for(bus, 2.0, lambda fr: fr[-1].arbitration_id == 0x580 + NODE)
    if not answer or answer[-1].arbitration_id != 0x580 + NODE:
        fail(f"no SDO answer to {bytes(payload).hex()}")
    return bytes(answer[-1].data)


def upload_expedited(bus, index, sub):
    r = sdo(bus, [0x40, index & 0xFF, index >> 8, sub, 0, 0, 0, 0])
    if r[0] & 0xE0 != 0x40 or not r[0] & 0x02:
        fail(f"0x{index:04X}:{sub}: not an expedited upload response: {r.hex()}")
    if r[1] | r[2] << 8 != index or r[3] != sub:
        fail(f"0x{index:04X}:{sub}: answer for another object: {r.hex()}")
    n = 4 - ((r[0] >> 2) & 3) if r[0] & 0x01 else 4
    return int.from_bytes(r[4:4 + n], "little")


def upload_segmented(bus, index, sub):
    r = sdo(bus, [0x40, index & 0xFF, index >> 8, sub, 0, 0, 0, 0])
    if r[0] & 0xE0 != 0x40 or r[0] & 0x02:
        fail(f"0x{index:04X}:{sub}: expected a segmented upload, got {r.hex()}")
    size = int.from_bytes(r[4:8], "little") if r[0] & 0x01 else None
    data, toggle = b"", 0
    while True:
        s = sdo(bus, [0x60 | toggle << 4, 0, 0, 0, 0, 0, 0, 0])
        if s[0] & 0xE0 != 0x00 or (s[0] >> 4) & 1 != toggle:
            fail(f"bad upload segment {s.hex()} (toggle {toggle})")
        data += s[1:8 - ((s[0] >> 1) & 7)]
        toggle ^= 1
        if s[0] & 0x01:
            break
    if size is not None and len(data) != size:
        fail(f"segmented upload gave {len(data)} bytes, the initiate said {size}")
    return data


def main():
    # The run's records go to a private directory, removed also when a check fails.
    with tempfile.TemporaryDirectory(prefix="omnitwin-pycanopen-") as out:
        check(out)


def check(out):
    omnitwin, scenario, eds, port = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
    spec = f"udp:{GROUP}:{port}"
    bus = can.Bus(interface="udp_multicast", channel=GROUP, port=port, receive_own_messages=False)
    run = subprocess.Popen([omnitwin, "run", scenario, "--bus", "canopen", "--clock", "realtime", "--out", out,
                            "--no-progress", "--set", f"bus.transport={spec}"],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        # 1. The running network: heartbeats, TPDO1s, SYNC and RPDO1s.
        want = {0x701, 0x702, 0x703, 0x704, 0x181, 0x182, 0x183, 0x184, 0x080, 0x201, 0x202, 0x203, 0x204}
        seen = receive_for(bus, 10.0, lambda fr: want <= {m.arbitration_id for m in fr})
        ids = {m.arbitration_id for m in seen}
        if not want <= ids:
            fail(f"missing {sorted(hex(i) for i in want - ids)} among {len(seen)} frames")
        print(f"saw {len(seen)} frames: heartbeats, SYNC, RPDO1 and TPDO1 of all four drives")

        # 2. Identity by hand, checked against the EDS.
        vendor, product = upload_expedited(bus, 0x1018, 1), upload_expedited(bus, 0x1018, 2)
        revision, serial = upload_expedited(bus, 0x1018, 3), upload_expedited(bus, 0x1018, 4)
        if vendor != int(eds_value(eds, "1018sub1", "DefaultValue"), 0):
            fail(f"vendor 0x{vendor:08X} is not the EDS's")
        if product != int(eds_value(eds, "1018sub2", "DefaultValue"), 0):
            fail(f"product 0x{product:08X} is not the EDS's")
        print(f"node {NODE} identity: vendor 0x{vendor:08X} product 0x{product:08X} revision 0x{revision:08X} serial {serial}")

        # 3. The device name with a segmented upload.
        name = upload_segmented(bus, 0x1008, 0).decode("latin-1")
        if name != eds_value(eds, "1008", "DefaultValue"):
            fail(f"device name {name!r} is not the EDS's")
        print(f"node {NODE} device name (segmented): {name!r}")

        # 4. A missing object: abort 0x06020000.
        r = sdo(bus, [0x40, 0x34, 0x12, 0x00, 0, 0, 0, 0])
        if r[0] != 0x80 or int.from_bytes(r[4:8], "little") != 0x06020000:
            fail(f"reading 0x1234 answered {r.hex()}, expected abort 0x06020000")
        print("0x1234: abort 0x06020000 (object does not exist)")
    finally:
        run.terminate()
        try:
            output, _ = run.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            run.kill()
            output, _ = run.communicate()
        bus.shutdown()
    print(output)
    print("PASS")


if __name__ == "__main__":
    main()
