#!/usr/bin/python3
"""python-can side of the UDP multicast interop tests (tests/bus_emulators/transport_udp_test.cpp).

Uses python-can's own `udp_multicast` interface (Debian's python3-can, run with
/usr/bin/python3), so the test checks our wire format against the reference implementation.

  python_can_udp.py recv GROUP PORT COUNT TIMEOUT_S
      Opens the bus, prints "READY", then prints one line per received message:
      "RX id=<hex> ext=<0|1> rtr=<0|1> err=<0|1> fd=<0|1> dlc=<n> data=<hex>"
      Exits 0 after COUNT messages, 2 on timeout.
  python_can_udp.py send GROUP PORT FRAME...
      Sends each FRAME and prints "SENT <n>". FRAME is ID:FLAGS:DLC:HEXDATA, where FLAGS is a
      subset of "x" (extended), "r" (remote), "e" (error), e.g. 000::2:0102 or 1abcdef0:x:1:ff.
"""
import sys
import time

import can


def fmt(msg):
    return "RX id=%x ext=%d rtr=%d err=%d fd=%d dlc=%d data=%s" % (
        msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame, msg.is_error_frame,
        msg.is_fd, msg.dlc, bytes(msg.data).hex())


def parse_frame(text):
    ident, flags, dlc, data = text.split(":")
    payload = bytes.fromhex(data)
    return can.Message(
        timestamp=time.time(),
        arbitration_id=int(ident, 16),
        is_extended_id="x" in flags,
        is_remote_frame="r" in flags,
        is_error_frame="e" in flags,
        dlc=int(dlc),
        data=payload,
        check=True,
    )


def main(argv):
    mode, group, port = argv[1], argv[2], int(argv[3])
    with can.Bus(interface="udp_multicast", channel=group, port=port) as bus:
        if mode == "recv":
            count, timeout = int(argv[4]), float(argv[5])
            print("READY", flush=True)
            deadline = time.monotonic() + timeout
            got = 0
            while got < count:
                left = deadline - time.monotonic()
                if left <= 0:
                    return 2
                msg = bus.recv(timeout=left)
                if msg is None:
                    continue
                print(fmt(msg), flush=True)
                got += 1
            return 0
        if mode == "send":
            frames = [parse_frame(a) for a in argv[4:]]
            for m in frames:
                bus.send(m)
            print("SENT %d" % len(frames), flush=True)
            return 0
    print("unknown mode " + mode, file=sys.stderr)
    return 64


if __name__ == "__main__":
    sys.exit(main(sys.argv))
