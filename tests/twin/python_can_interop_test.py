#!/usr/bin/python3
# Tests that a python-can script (python3-can from Debian, interface udp_multicast) joins the
# UDP bus of `omnitwin run --bus can` (master and twin as two processes, realtime clock): it
# sees the master's command frames and the slaves' feedback, its node-detection request is
# answered by the master and all four slaves, and an NMT stop it sends is obeyed: the slaves
# stop sending feedback (metrics.json: all stopped), the master stops commanding and logs the
# stop (master.log: in real time it keeps its own clock and does not report to the twin), and
# the twin counts python-can's two frames as a foreign sender's (bus.foreign_frames).
#
# Usage: python_can_interop_test.py OMNITWIN SCENARIO PORT
import json
import os
import subprocess
import sys
import tempfile
import time

import can

GROUP = "239.74.163.2"
FEEDBACK_IDS = {0x202, 0x302, 0x502, 0x602}
SLAVES = {0x04, 0x08, 0x10, 0x20}


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


def receive_for(bus, seconds, until=None):
    """Frames received within `seconds` (or until until(frames) holds), with arrival times."""
    frames = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        m = bus.recv(timeout=0.05)
        if m is not None:
            frames.append((time.monotonic(), m))
            if until and until(frames):
                break
    return frames


def main():
    # The run's records go to a private directory, removed also when a check fails.
    with tempfile.TemporaryDirectory(prefix="omnitwin-pycan-") as out:
        check(out)


def check(out):
    omnitwin, scenario, port = sys.argv[1], sys.argv[2], int(sys.argv[3])
    spec = f"udp:{GROUP}:{port}"
    bus = can.Bus(interface="udp_multicast", channel=GROUP, port=port, receive_own_messages=False)
    run = subprocess.Popen([omnitwin, "run", scenario, "--bus", "can", "--clock", "realtime", "--out", out,
                            "--no-progress", "--set", f"bus.transport={spec}"],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        # 1. The running system: master commands (0x102) and every slave's feedback.
        def running(frames):
            ids = [m.arbitration_id for _, m in frames if not m.is_remote_frame]
            return ids.count(0x102) >= 20 and all(ids.count(f) >= 5 for f in FEEDBACK_IDS)
        seen = receive_for(bus, 8.0, running)
        if not running(seen):
            fail(f"did not see the running system: {sorted(set(hex(m.arbitration_id) for _, m in seen))}")
        print(f"saw {len(seen)} frames: commands 0x102 and feedback from all four slaves")

        # 2. Node detection from python: remote frame ID 0, answers are remote frames with node IDs.
        bus.send(can.Message(arbitration_id=0x000, is_remote_frame=True, dlc=0, is_extended_id=False))
        answers = receive_for(bus, 1.0, lambda fr: {m.arbitration_id for _, m in fr if m.is_remote_frame} >= SLAVES | {0x02})
        answered = {m.arbitration_id for _, m in answers if m.is_remote_frame and m.arbitration_id != 0}
        if not (SLAVES | {0x02}) <= answered:
            fail(f"detection answers {sorted(hex(a) for a in answered)}, expected master 0x02 and slaves")
        print("detection answered by", sorted(hex(a) for a in answered))

        # 3. NMT stop to all nodes (0x000 [00 02]): slaves and master must stop.
        bus.send(can.Message(arbitration_id=0x000, data=[0x00, 0x02], is_extended_id=False))
        t_stop = time.monotonic()
        after = receive_for(bus, 1.0)
        late = [m for t, m in after if t > t_stop + 0.2 and m.arbitration_id in FEEDBACK_IDS | {0x102}]
        if late:
            fail(f"{len(late)} command/feedback frames more than 200 ms after the NMT stop, e.g. {late[0]}")
        print("after NMT stop: no commands or feedback")
    finally:
        try:
            output, _ = run.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            run.kill()
            output, _ = run.communicate()
        bus.shutdown()
    print(output)
    if run.returncode not in (0, 1):
        fail(f"omnitwin run exited {run.returncode}")
    with open(os.path.join(out, "metrics.json")) as f:
        m = json.load(f)
    # In real time the master keeps its own clock and reports only in its log.
    with open(os.path.join(out, "master.log")) as f:
        log = f.read()
    if "stopped (nmt_stop" not in log:
        fail("the master's log does not show it stopping on the NMT stop:\n" + log)
    states = [s["state"] for s in m["slaves"]]
    if any(s != "stopped" for s in states):
        fail(f"slave states {states}, expected all stopped")
    # python-can is a second sender on the twin's transport: its two frames are counted (and,
    # without bus.refuse_foreign, obeyed as above).
    if m["bus"].get("foreign_frames") != 2 or m["bus"].get("refused_frames") != 0:
        fail(f"foreign/refused frames {m['bus'].get('foreign_frames')}/{m['bus'].get('refused_frames')}, expected 2/0")
    print("PASS: python-can saw the bus, detection answered, NMT stop obeyed by master and slaves; "
          "its 2 frames counted as a foreign sender's")


if __name__ == "__main__":
    main()
