#!/usr/bin/python3
"""Plots what each emulated bus costs per slave and cycle against the slave count (issue 17,
item 4), from the Google Benchmark JSON files scripts/bench writes:

  ec_scaling.json   BM_EcCycle/N     against BM_EcDrivesOnly/N   (EtherCAT: master + ESC chain)
  can_scaling.json  BM_CanCycle/N    against BM_CanDrivesOnly/N  (CANopen on the simulated wire)
  m3_cycle.json     BM_M3Cycle/N     against BM_DrivesOnly/N     (MECHATROLINK-III line model)

The bus's share = (cycle - drives alone) / N, in microseconds; medians where the run had
repetitions. Writes OUT.png (default docs/images/bus_scaling.png).

  tests/bench/plot_bus_scaling.py BENCH_DIR [OUT.png]
"""
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402

TO_US = {"ns": 1e-3, "us": 1.0, "ms": 1e3, "s": 1e6}


def times_us(path, prefix):
    """{N: real time per iteration [us]} of the benchmarks named PREFIX/N (medians if any)."""
    with open(path) as f:
        runs = json.load(f)["benchmarks"]
    medians = [r for r in runs if r.get("aggregate_name") == "median"]
    rows = medians if medians else [r for r in runs if r.get("run_type", "iteration") == "iteration"]
    out = {}
    for r in rows:
        name = r.get("run_name", r["name"])
        if not name.startswith(prefix + "/"):
            continue
        n = int(name.split("/")[1])
        out[n] = r["real_time"] * TO_US[r.get("time_unit", "ns")]
    return out


def per_slave(path, cycle, drives):
    c, d = times_us(path, cycle), times_us(path, drives)
    ns = sorted(n for n in c if n in d)
    return ns, [(c[n] - d[n]) / n for n in ns]


def main():
    bench = sys.argv[1]
    out = sys.argv[2] if len(sys.argv) > 2 else "docs/images/bus_scaling.png"
    series = [
        ("EtherCAT (master + ESC chain)", "ec_scaling.json", "BM_EcCycle", "BM_EcDrivesOnly"),
        ("CANopen (SYNC, RPDO, TPDO on the wire)", "can_scaling.json", "BM_CanCycle", "BM_CanDrivesOnly"),
        ("MECHATROLINK-III (C1 master + line)", "m3_cycle.json", "BM_M3Cycle", "BM_DrivesOnly"),
    ]
    fig, ax = plt.subplots(figsize=(7, 4.2))
    drawn = 0
    for label, file, cycle, drives in series:
        path = os.path.join(bench, file)
        if not os.path.exists(path):
            print(f"plot_bus_scaling: {path} missing, {label} left out", file=sys.stderr)
            continue
        ns, us = per_slave(path, cycle, drives)
        if ns:
            ax.plot(ns, us, marker="o", label=label)
            drawn += 1
    if drawn == 0:
        sys.exit("plot_bus_scaling: no benchmark results in " + bench)
    ax.set_xscale("log", base=2)
    ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda x, _: f"{x:g}"))
    ax.set_xlabel("slaves (nodes) on the bus")
    ax.set_ylabel("bus emulation per slave and cycle [µs]")
    ax.set_title("Bus emulation cost per slave, above the drives (in process)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
