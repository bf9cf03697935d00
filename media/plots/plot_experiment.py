#!/usr/bin/python3
"""media layer — plots of the `omnitwin experiment` outputs (can-timing, can-dropout, thesis-platform,
m3-cycle).

Called by twin/experiment.cpp as `plot_experiment.py KIND CSV OUT_DIR`; reads the CSV the
experiment wrote and draws PNGs beside it. Kept in Python so the C++ side needs no plotting
library; Agg backend, so no display is needed. Exit 3 when matplotlib is missing (the caller
names the Debian package), 2 on bad usage.
"""
import csv
import os
import sys

try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    sys.stderr.write("plot_experiment.py: matplotlib is missing (Debian: python3-matplotlib)\n")
    sys.exit(3)


def read_rows(path):
    """The CSV as a list of dicts with numbers converted where they parse."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        for k, v in r.items():
            try:
                r[k] = float(v) if "." in v else int(v)
            except ValueError:
                pass
    return rows


def select(rows, **want):
    """Rows whose fields equal every keyword, sorted by data bytes."""
    out = [r for r in rows if all(r[k] == v for k, v in want.items())]
    return sorted(out, key=lambda r: r["bytes"])


def save(fig, out_dir, name):
    """Writes one PNG and closes the figure."""
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, name), dpi=110)
    plt.close(fig)


def plot_timing(rows, out_dir):
    """Table 2-2: our T_tx (lines) beside the thesis's (markers), one colour per bit rate."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for rate in sorted({r["rate_kbps"] for r in rows}, reverse=True):
        sel = select(rows, rate_kbps=rate)
        x = [r["bytes"] for r in sel]
        line, = ax.plot(x, [r["ours_ms"] for r in sel], "-", label=f"{rate} kbit/s ours")
        ax.plot(x, [r["thesis_ms"] for r in sel], "o", color=line.get_color(), label=f"{rate} kbit/s thesis")
    ax.set_yscale("log")
    ax.set_xlabel("data bytes")
    ax.set_ylabel("T_tx [ms]")
    ax.set_title("Table 2-2: CAN transmission time, twin bus vs thesis")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    save(fig, out_dir, "can_timing.png")


def lines(ax, rows, key, label_of, style_of=lambda r: "-o", **want):
    """One line of `key` over data bytes per distinct label among the selected rows."""
    sel = select(rows, **want)
    first = {}
    for r in sel:
        first.setdefault(label_of(r), r)
    order = lambda lab: (first[lab]["sync"], first[lab]["messages"], first[lab]["period_ms"],
                         -first[lab]["rate_kbps"], first[lab]["clock"])
    for label in sorted(first, key=order):
        pts = [r for r in sel if label_of(r) == label]
        ax.plot([r["bytes"] for r in pts], [r[key] for r in pts], style_of(pts[0]), label=label)
    ax.set_xlabel("data bytes")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)


def sync_label(r):
    return ("sync" if r["sync"] else "no sync") + f", N={r['messages']}"


def plot_size(rows, out_dir):
    """Figs. 2-18 / 3-24: p without and with sync, and N_drift, over data size (1000 kbit/s, 5 ms)."""
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(13, 4))
    for ax, sync in ((a, 0), (b, 1)):
        lines(ax, rows, "p_percent", sync_label, rate_kbps=1000, period_ms=5, clock="rate", sync=sync)
        ax.set_ylabel("dropout p [%]")
    a.set_title("Fig. 2-18: 1000 kbit/s, 5 ms, no sync")
    b.set_title("Fig. 3-24: with sync")
    lines(c, rows, "n_drift", sync_label, rate_kbps=1000, period_ms=5, clock="rate", sync=0)
    c.set_ylabel("N_drift [samples]")
    c.set_title("N_drift (eq. 2-3), no sync")
    save(fig, out_dir, "can_dropout_size.png")


def rate_messages(rows, period):
    """The message count the bit-rate sweep used at `period` (the one 100 kbit/s has)."""
    return max(r["messages"] for r in rows if r["period_ms"] == period and r["rate_kbps"] == 100)


def plot_rates(rows, out_dir, period, figs, name):
    """Figs. 2-19 / 3-25 … 3-28: p over data size per bit rate, without and with sync."""
    n = rate_messages(rows, period)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, sync in zip(axes, (0, 1)):
        lines(ax, rows, "p_percent", lambda r: f"{r['rate_kbps']} kbit/s", period_ms=period, messages=n,
              sync=sync, clock="rate")
        ax.set_title(f"{figs[sync]}: {period} ms, N={n}, " + ("sync" if sync else "no sync"))
        ax.set_ylabel("dropout p [%]")
    save(fig, out_dir, name)


def plot_period(rows, out_dir):
    """Figs. 2-20 / 2-21: p and N_drift per sampling period (rate clock solid, isr-lag dashed)."""
    n = max(r["messages"] for r in rows if r["period_ms"] == 10)
    label = lambda r: f"{r['period_ms']} ms, {r['clock']}"
    style = lambda r: "-o" if r["clock"] == "rate" else "--s"
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    lines(a, rows, "p_percent", label, style, rate_kbps=1000, messages=n, sync=0)
    a.set_ylabel("dropout p [%]")
    a.set_title(f"Fig. 2-20: 1000 kbit/s, N={n}")
    lines(b, rows, "n_drift", label, style, rate_kbps=1000, messages=n, sync=0)
    b.set_ylabel("N_drift [samples]")
    b.set_title("Fig. 2-21: N_drift by period")
    save(fig, out_dir, "can_dropout_period.png")


def plot_count(rows, out_dir):
    """Figs. 2-22 / 2-23: p and N_drift per message count at 1 ms, 1000 kbit/s."""
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    lines(a, rows, "p_percent", sync_label, rate_kbps=1000, period_ms=1, clock="rate")
    a.set_ylabel("dropout p [%]")
    a.set_title("Fig. 2-22: 1000 kbit/s, 1 ms")
    lines(b, rows, "n_drift", sync_label, rate_kbps=1000, period_ms=1, clock="rate", sync=0)
    b.set_ylabel("N_drift [samples]")
    b.set_title("Fig. 2-23: N_drift by message count")
    save(fig, out_dir, "can_dropout_count.png")


def plot_dropout(rows, out_dir):
    plot_size(rows, out_dir)
    plot_rates(rows, out_dir, 5, {0: "Figs. 2-19/3-25", 1: "Fig. 3-26"}, "can_dropout_rate_5ms.png")
    plot_rates(rows, out_dir, 1, {0: "Fig. 3-27", 1: "Fig. 3-28"}, "can_dropout_rate_1ms.png")
    plot_period(rows, out_dir)
    plot_count(rows, out_dir)


def plot_platform(rows, out_dir):
    """Tables 4-3 … 4-12: contour and axis IAE by bit rate, without/with sync; one row of
    panels per slave-clock reading of the twin (means, bars over the trials' min … max), then
    the thesis's."""
    clocks = list(dict.fromkeys(r["clock"] for r in rows))
    rates = sorted({r["rate_kbps"] for r in rows})
    x = range(len(rates))
    panels = [(c, c) for c in clocks] + [(clocks[0], "thesis")]
    fig, axes = plt.subplots(len(panels), 2, figsize=(10, 3.3 * len(panels)), squeeze=False)
    for col, (ours, thesis, unit) in enumerate((("iae_contour_cm", "thesis_iae_contour_cm", "cm"),
                                                ("axis_iae_pulse", "thesis_axis_iae_pulse", "pulses"))):
        for row, (clock, who) in enumerate(panels):
            key = thesis if who == "thesis" else ours
            ax = axes[row][col]
            lo_key, hi_key = (None, None) if who == "thesis" else \
                ((f"{ours[:-3]}_min_cm", f"{ours[:-3]}_max_cm") if col == 0 else ("axis_iae_min_pulse", "axis_iae_max_pulse"))
            for off, sync in ((-0.2, 0), (0.2, 1)):
                sel = [next(r for r in rows if r["rate_kbps"] == k and r["sync"] == sync and r["clock"] == clock)
                       for k in rates]
                vals = [r[key] for r in sel]
                # The spread over the trials (min … max) where the CSV has it.
                err = None
                if lo_key and lo_key in sel[0]:
                    err = [[v - r[lo_key] for v, r in zip(vals, sel)], [r[hi_key] - v for v, r in zip(vals, sel)]]
                ax.bar([i + off for i in x], vals, width=0.4, yerr=err, capsize=3, label="sync" if sync else "no sync")
            ax.set_xticks(list(x))
            ax.set_xticklabels([f"{k} kbit/s" for k in rates])
            ax.set_ylabel(f"{'contour' if col == 0 else 'axis'} IAE [{unit}]")
            title = "thesis" if who == "thesis" else f"twin, {clock} slave clocks"
            ax.set_title(f"{title}: {'platform contour' if col == 0 else 'mean axis velocity'} IAE", fontsize=9)
            ax.legend(fontsize=7)
            ax.grid(True, axis="y", alpha=0.3)
    save(fig, out_dir, "thesis_platform_iae.png")


def plot_platform_time(rows, out_dir):
    """Seed 002's figs. 4-21 … 4-28 as the twin sees them: the odometric X, Y and contour error
    over time at one bit rate, without and with sync, one panel each (one run of each)."""
    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    for sync, style in ((0, "-"), (1, "-")):
        sel = [r for r in rows if r["sync"] == sync]
        t = [r["t_s"] for r in sel]
        for ax, key, name in zip(axes, ("ex_cm", "ey_cm", "ec_cm"), ("X", "Y", "contour")):
            ax.plot(t, [r[key] for r in sel], style, linewidth=0.8, alpha=0.85, label="sync" if sync else "no sync")
            ax.set_ylabel(f"{name} error [cm]")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
    rate = rows[0]["rate_kbps"] if rows else 0
    axes[0].set_title(f"twin, {rate} kbit/s: odometric pose error (planned − odometry) without and with sync", fontsize=9)
    axes[-1].set_xlabel("t [s]")
    save(fig, out_dir, "thesis_platform_time.png")


def plot_m3_cycle(rows, out_dir):
    """M-III shortest transmission cycle over slave count: one panel per topology, one colour
    per data length; 1 retry slot solid, 0 and 2 retry slots the band around it; the
    0.125/0.25/0.5/1 ms cycles as dashed lines."""
    topologies = ["cascade", "star"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), sharey=True)
    for ax, topo in zip(axes, topologies):
        for n_bytes in sorted({r["data_bytes"] for r in rows}):
            curve = {}
            for retry in (0, 1, 2):
                sel = sorted((r for r in rows if r["topology"] == topo and r["data_bytes"] == n_bytes
                              and r["retry_slots"] == retry), key=lambda r: r["slaves"])
                curve[retry] = ([r["slaves"] for r in sel], [r["min_cycle_ns"] / 1e6 for r in sel])
            line, = ax.plot(*curve[1], "-", label=f"{n_bytes} B")
            ax.fill_between(curve[0][0], curve[0][1], curve[2][1], color=line.get_color(), alpha=0.15)
        for budget in (0.125, 0.25, 0.5, 1.0):
            ax.axhline(budget, color="grey", linestyle="--", linewidth=0.8)
            ax.text(1, budget, f" {budget} ms", va="bottom", fontsize=7, color="grey")
        ax.set_yscale("log")
        ax.set_xlabel("slaves")
        ax.set_title(f"{topo}, 10 m cables (band: 0 … 2 retry slots)", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    axes[0].set_ylabel("shortest transmission cycle [ms]")
    save(fig, out_dir, "m3_cycle.png")


def main(argv):
    kinds = {"can-timing": plot_timing, "can-dropout": plot_dropout, "thesis-platform": plot_platform,
             "thesis-platform-time": plot_platform_time, "m3-cycle": plot_m3_cycle}
    if len(argv) != 4 or argv[1] not in kinds:
        sys.stderr.write("usage: plot_experiment.py can-timing|can-dropout|thesis-platform|thesis-platform-time|m3-cycle CSV OUT_DIR\n")
        return 2
    kinds[argv[1]](read_rows(argv[2]), argv[3])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
