#!/usr/bin/python3
"""media layer — the plot of `omnitwin sweep`: one metric against one swept parameter.

Called as `sweep_plot.py CSV PNG X Y PARAM...` (by media/run_report.cpp). CSV is the sweep's
table (point, the parameters, the metrics, passed, exit_code). Draws Y against X, one line per
combination of the other parameters (the legend names them), marks points whose expectations
failed with a cross, leaves out points without the metric, and writes PNG under a temporary
name then renames it. Non-numeric X values (e.g. a list) are placed in their table order.
Exit 0 on success, 2 on bad usage or a table without the columns, 3 when the file cannot be
written.
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def number(text):
    """The float of a cell, or None."""
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


def main(argv):
    if len(argv) < 5:
        print("usage: sweep_plot.py CSV PNG X Y PARAM...", file=sys.stderr)
        return 2
    table, out, x, y, params = argv[1], argv[2], argv[3], argv[4], argv[5:]
    with open(table, newline="") as f:
        rows = list(csv.DictReader(f))
    if rows and (x not in rows[0] or y not in rows[0]):
        print(f"sweep_plot.py: {table} has no column {x!r} or {y!r}", file=sys.stderr)
        return 2
    others = [p for p in params if p != x]
    order = {}  # X values in their first appearance, for non-numeric X
    groups = {}
    for r in rows:
        order.setdefault(r[x], len(order))
        label = ", ".join(f"{p}={r[p]}" for p in others) or y
        groups.setdefault(label, []).append(r)
    numeric_x = all(number(v) is not None for v in order)
    fig, ax = plt.subplots(figsize=(8, 5), dpi=100)
    for label, rs in groups.items():
        pts = []
        for r in rs:
            yv = number(r[y])
            if yv is None:
                continue
            xv = number(r[x]) if numeric_x else order[r[x]]
            pts.append((xv, yv, r.get("passed") == "true"))
        pts.sort()
        if not pts:
            continue
        line = ax.plot([p[0] for p in pts], [p[1] for p in pts], marker="o", label=label)[0]
        bad = [p for p in pts if not p[2]]
        if bad:
            ax.plot([p[0] for p in bad], [p[1] for p in bad], "x", color=line.get_color(), markersize=11)
    if not numeric_x:
        ax.set_xticks(list(order.values()))
        ax.set_xticklabels(list(order.keys()), rotation=20)
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    ax.set_title(f"{y} against {x} ({len(rows)} points; x = expectations failed)")
    ax.grid(True, alpha=0.3)
    if len(groups) > 1:
        ax.legend(fontsize=8)
    fig.tight_layout()
    temp = os.path.join(os.path.dirname(os.path.abspath(out)), "." + os.path.basename(out) + ".part.png")
    try:
        fig.savefig(temp)
        os.replace(temp, out)
    except OSError as e:
        print(f"sweep_plot.py: cannot write {out}: {e}", file=sys.stderr)
        return 3
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
