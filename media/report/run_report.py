#!/usr/bin/python3
"""media layer — the run report: RUN_DIR/report.html and RUN_DIR/plots/*.png.

Called as `run_report.py RUN_DIR` (by media/run_report.cpp after `omnitwin run`, or by hand
on a run directory copied from elsewhere). Reads only the files of the run directory
(docs/run-directory.md) and tolerates every optional one being absent: an older run without
run.json or bus.csv, an interrupted run with a partial trajectory.csv, a run that died
before metrics.json. Absences are noted in the page, never a crash.

The page is one self-contained HTML file (inline CSS, no JavaScript, no external URLs) that
links the run's own files by relative name, so the directory can be moved or archived as a
whole. Output is deterministic for the same inputs (no wall-clock timestamps). Every file
is written to a temporary name and renamed. Exit 0 on success, 2 on bad usage or a missing
or invalid run directory, 3 when matplotlib is missing (Debian: python3-matplotlib).
"""
import csv
import html
import io
import json
import math
import os
import re
import sys
import urllib.parse

from report_common import metric_at

try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    sys.stderr.write("run_report.py: matplotlib is missing (Debian: python3-matplotlib)\n")
    sys.exit(3)

PLOT_DPI = 80
MAX_PLOT_POINTS = 3000          # longer series are decimated for drawing only
MAX_EVENTS = 500                # events.log rows shown in the page
RUN_FILES = ("run.json", "metrics.json", "trajectory.csv", "events.log")
PLOT_NAMES = ("path.png", "errors.png", "wheels.png", "bus.png")
TRAJECTORY_PLOTS = ("Path vs reference", "Pose errors over time", "Wheel speeds vs commands")
# Linked files in page order: (name, what it is).
LINKED_FILES = (
    ("trajectory.csv", "every control sample: reference, pose, odometry, commands, wheels"),
    ("bus.csv", "cumulative bus statistics per control sample"),
    ("metrics.json", "the run's metrics and expectation result"),
    ("run.json", "what ran: scenario, bus, clock, faults, expectations"),
    ("events.log", "run events"),
    ("master.log", "the master process's output"),
    ("master.yaml", "the master process's configuration"),
    ("master-platform.yaml", "the master's platform loop"),
    ("master-stats.json", "the master's counters when it ended"),
    ("realtime.csv", "realtime runs: tick lateness per second of sim time"),
    ("platform.xml", "the MJCF model MuJoCo compiled"),
)
POSE_METRICS = ("final_error_cm", "max_error_cm", "iae_contour_cm", "std_contour_cm",
                "iae_x_cm", "std_x_cm", "iae_y_cm", "std_y_cm",
                "final_phi_error_deg", "max_phi_error_deg", "iae_phi_deg", "std_phi_deg")
DRIVE_STATES = ("off", "waiting", "running", "syncing", "fault")
# metrics.json groups the metrics section shows in its own tables (the expectations have
# their own section), and top-level values the header already shows.
SHOWN_GROUPS = ("platform", "platform_odometry", "bus", "drives", "master", "realtime", "physics",
                "expectations")
HEADER_SCALARS = ("scenario", "scenario_file", "clock", "sim_time_s", "wall_time_s", "real_time_factor")
FAULT_COLOR = "tab:red"
EVENT_LINE = re.compile(r"^\s*(\S+)\s+(\S+)\s*(.*)$")   # events.log: time, kind, message
CSS = """
body{font-family:sans-serif;margin:1.5em auto;max-width:1100px;color:#222;padding:0 1em}
h1{margin-bottom:.2em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
.desc{color:#555;margin-top:0}
.banner{font-size:1.4em;font-weight:bold;padding:.5em .8em;border-radius:6px;margin:.8em 0}
.banner.pass{background:#dff3df;color:#14591a;border:2px solid #2e8b37}
.banner.fail{background:#fbe0e0;color:#8a1111;border:2px solid #c62828}
.banner.warn{background:#fff1d6;color:#7a4a00;border:2px solid #e69500}
.banner .sub{display:block;font-size:.65em;font-weight:normal;margin-top:.2em}
table{border-collapse:collapse;margin:.5em 0;font-size:.92em}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:left;vertical-align:top}
th{background:#f2f2f2}td.num{text-align:right;font-family:monospace}
td.PASS{background:#dff3df;color:#14591a;font-weight:bold}
td.FAIL{background:#fbe0e0;color:#8a1111;font-weight:bold}
td.NOTEVALUATED{background:#fff1d6;color:#7a4a00;font-weight:bold}
tr.ev-fault td,tr.ev-error td,tr.ev-interrupt td{background:#fbe0e0}
.scroll{overflow-x:auto}.note{color:#7a4a00}
.plots img{max-width:100%;display:block;margin:.5em 0 1.2em 0;border:1px solid #ddd}
video{max-width:100%;border:1px solid #ddd}
summary{cursor:pointer}summary h2{display:inline}
code{background:#f4f4f4;padding:0 .2em}
"""


# ---------------------------------------------------------------------------------------
# Reading the run directory

def load_json(path):
    """(value, problem): the parsed file, or None and why ("absent" or the parse error)."""
    if not os.path.isfile(path):
        return None, "absent"
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f), None
    except (OSError, ValueError) as e:
        return None, f"unreadable ({e})"


def number(v):
    """v as a float when it is a JSON number (not a bool), else None."""
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None


def to_float(text):
    """A CSV cell as a float; NaN for anything that does not parse."""
    try:
        return float(text)
    except ValueError:
        return math.nan


def read_table(path):
    """(columns, rows, problem): a CSV as {name: [float]}; a partial last line is dropped.

    An interrupted run may leave a line cut short; rows whose cell count differs from the
    header are skipped and counted in `problem`.
    """
    if not os.path.isfile(path):
        return {}, 0, "absent"
    try:
        with open(path, encoding="utf-8", newline="") as f:
            text = f.read()
    except (OSError, UnicodeDecodeError) as e:
        return {}, 0, f"unreadable ({e})"
    notes = []
    if text and not text.endswith("\n"):
        text = text[:text.rfind("\n") + 1]
        notes.append("last line incomplete, dropped")
    reader = csv.reader(io.StringIO(text))
    header = next(reader, None)
    if not header:
        return {}, 0, "empty"
    values = [[] for _ in header]
    skipped = 0
    for row in reader:
        if len(row) != len(header):
            skipped += 1
            continue
        for col, cell in zip(values, row):
            col.append(to_float(cell))
    if skipped:
        notes.append(f"{skipped} malformed rows skipped")
    rows = len(values[0])
    return dict(zip(header, values)), rows, "; ".join(notes) or None


def read_events(path):
    """(events, problem): events.log as [(time text, kind, message)]."""
    if not os.path.isfile(path):
        return [], "absent"
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            lines = f.read().splitlines()
    except OSError as e:
        return [], f"unreadable ({e})"
    events = []
    for line in lines:
        m = EVENT_LINE.match(line)
        if m:
            events.append((m.group(1), m.group(2), m.group(3)))
    return events, None


# ---------------------------------------------------------------------------------------
# Formatting

def esc(text):
    """HTML-escaped text of anything."""
    return html.escape(str(text), quote=True)


def href(name):
    """A relative file name as an URL-escaped attribute value."""
    return esc(urllib.parse.quote(name))


def fmt_value(v):
    """A metric value for display: integers as such, floats with 6 significant digits."""
    if v is None:
        return "—"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, (dict, list)):
        return json.dumps(v, sort_keys=True)
    return str(v)


def fmt_size(n):
    """A byte count for people (decimal units)."""
    if n < 1000:
        return f"{n} B"
    if n < 1000 * 1000:
        return f"{n / 1000:.1f} kB"
    return f"{n / 1e6:.1f} MB"


def cell(v):
    """One <td>, right-aligned for numbers."""
    cls = ' class="num"' if isinstance(v, (int, float)) and not isinstance(v, bool) else ""
    return f"<td{cls}>{esc(fmt_value(v))}</td>"


def kv_table(obj):
    """A two-column table of an object's scalar members (nested ones as JSON)."""
    rows = "".join(f"<tr><th>{esc(k)}</th>{cell(obj[k])}</tr>" for k in sorted(obj))
    return f"<table>{rows}</table>"


def grid_table(header, rows):
    """A table with a header row; rows are lists of values (or pre-rendered <td> strings)."""
    head = "".join(f"<th>{esc(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(c if isinstance(c, str) and c.startswith("<td")
                                    else cell(c) for c in r) + "</tr>" for r in rows)
    return f'<div class="scroll"><table><tr>{head}</tr>{body}</table></div>'


# ---------------------------------------------------------------------------------------
# Expectations

def interrupted_in_outputs(metrics):
    """True when a signal came after the run loop's end, while the video or report was made:
    the run and its records are whole and its expectations were judged."""
    return bool(metrics) and bool(metrics.get("interrupted")) and metrics.get("interrupted_phase") == "outputs"


def run_cut_short(metrics):
    """True when the run was interrupted or failed, so bounds were not evaluated."""
    return (bool(metrics) and (bool(metrics.get("interrupted")) or "error" in metrics)
            and not interrupted_in_outputs(metrics))


def check_bound(expectation, metrics):
    """(value, status, reason) of one run.json expectation against metrics.json.

    Mirrors twin/expectations.cpp: an absent, non-numeric or non-finite value fails.
    """
    name = str(expectation.get("metric", "?"))
    lo, hi = number(expectation.get("min")), number(expectation.get("max"))
    found, v = metric_at(metrics, name)
    if not found:
        return None, "FAIL", "missing from metrics"
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return v, "FAIL", "not a number"
    if not math.isfinite(v):
        return v, "FAIL", "not finite"
    if hi is not None and v > hi:
        return v, "FAIL", f"> max {fmt_value(hi)}"
    if lo is not None and v < lo:
        return v, "FAIL", f"< min {fmt_value(lo)}"
    return v, "PASS", ""


def bound_text(expectation):
    """`min ≤ x ≤ max` style text of one expectation's bounds."""
    lo, hi = expectation.get("min"), expectation.get("max")
    if lo is not None and hi is not None:
        return f"{fmt_value(lo)} ≤ x ≤ {fmt_value(hi)}"
    if hi is not None:
        return f"x ≤ {fmt_value(hi)}"
    if lo is not None:
        return f"x ≥ {fmt_value(lo)}"
    return "none"


def expectations_section(run, metrics):
    """The expectations: one row per bound of run.json, then metrics.json's failures."""
    parts = ["<h2>Expectations</h2>"]
    bounds = run.get("expectations") if isinstance(run, dict) else None
    cut_short = run_cut_short(metrics)
    if not isinstance(bounds, list):
        parts.append('<p class="note">run.json is absent or lists no expectations: '
                     'the bounds are not known; only the run\'s own verdict is shown.</p>')
    elif not bounds:
        parts.append("<p>The scenario sets no expectations.</p>")
    elif metrics is None:
        parts.append('<p class="note">metrics.json is absent: the bounds cannot be checked.</p>')
    else:
        rows = []
        for e in bounds:
            e = e if isinstance(e, dict) else {}
            value, status, reason = check_bound(e, metrics)
            if cut_short:
                status, reason = "NOT EVALUATED", "the run was cut short"
            rows.append([e.get("metric", "?"), bound_text(e), value,
                         f'<td class="{status.replace(" ", "")}">{esc(status)}</td>', reason])
        parts.append(grid_table(["metric", "bound", "value", "result", "why"], rows))
        parts.append(agreement_note(rows, metrics, cut_short))
    parts.append(verdict_html(metrics))
    return "".join(parts)


def agreement_note(rows, metrics, cut_short):
    """A note when the bounds above and the run's own verdict disagree."""
    ex = group(metrics, "expectations")
    if cut_short or "passed" not in ex:
        return ""
    failed = sum(1 for r in rows if 'class="FAIL"' in r[3])
    if (failed == 0) == (ex["passed"] is True):
        return ""
    why = (" (the run also fails on other checks, e.g. physics warnings)" if failed == 0 else
           " (run.json and metrics.json may come from different runs)")
    return f'<p class="note">The bounds checked here and the run\'s own verdict differ{why}.</p>'


def verdict_html(metrics):
    """The run's own verdict from metrics.json expectations.{passed, failures}."""
    if metrics is None:
        return ""
    ex = metrics.get("expectations")
    if not isinstance(ex, dict):
        return '<p class="note">metrics.json holds no expectation result.</p>'
    passed = ex.get("passed") is True
    failures = ex.get("failures") if isinstance(ex.get("failures"), list) else []
    if interrupted_in_outputs(metrics):
        # The bounds were judged, but a run a signal cut during its outputs does not pass.
        text = ("<p>Run verdict (metrics.json): <b>INTERRUPTED</b> (a signal while the video or "
                f"report was made); the expectations alone: {'met' if passed else 'FAILED'}")
    else:
        text = f"<p>Run verdict (metrics.json): <b>{'passed' if passed else 'FAILED'}</b>"
    if not failures:
        return text + ", no failures.</p>"
    items = "".join(f"<li>{esc(f)}</li>" for f in failures)
    return text + f", {len(failures)} failure(s):</p><ul class=\"failures\">{items}</ul>"


# ---------------------------------------------------------------------------------------
# Header and metrics tables

def status_banner(metrics, metrics_problem):
    """The prominent status line: passed, failed, interrupted, error or no metrics."""
    if metrics is None:
        why = "absent" if metrics_problem == "absent" else metrics_problem
        return ('<div class="banner warn">NO METRICS<span class="sub">metrics.json is '
                f'{esc(why)}: the run did not finish (still running, killed or crashed).'
                '</span></div>')
    banners = []
    if "error" in metrics:
        banners.append(f'<div class="banner fail">ERROR<span class="sub">{esc(metrics["error"])}'
                       '</span></div>')
    if interrupted_in_outputs(metrics):
        ex = group(metrics, "expectations")
        judged = "met" if ex.get("passed") is True else "not all met"
        banners.append('<div class="banner warn">INTERRUPTED<span class="sub">a signal came after '
                       f'the run had ended (t = {esc(fmt_value(metrics.get("sim_time_s")))} s), '
                       'while its video or this report was being made: the run and its records '
                       f'are whole and its expectations were judged ({judged}), but the video may '
                       'stop before the run\'s end, and the run does not pass.</span></div>')
    elif metrics.get("interrupted"):
        banners.append('<div class="banner warn">INTERRUPTED<span class="sub">the run was stopped '
                       f'at t = {esc(fmt_value(metrics.get("sim_time_s")))} s; the records hold '
                       'a part of it and the expectations were not evaluated.</span></div>')
    if not banners:
        ex = group(metrics, "expectations")
        if ex.get("passed") is True:
            banners.append('<div class="banner pass">PASSED<span class="sub">all expectations met'
                           '</span></div>')
        else:
            failures = ex.get("failures")
            n = len(failures) if isinstance(failures, list) else 0
            banners.append(f'<div class="banner fail">FAILED<span class="sub">{n} expectation '
                           'failure(s)</span></div>')
    return "".join(banners)


def group(metrics, name):
    """A metric group (an object member of metrics.json), or {} when absent or malformed."""
    g = metrics.get(name) if isinstance(metrics, dict) else None
    return g if isinstance(g, dict) else {}


def first_of(key, *sources):
    """The first source (dict) that has `key`, its value; else None."""
    for s in sources:
        if isinstance(s, dict) and s.get(key) is not None:
            return s[key]
    return None


def bus_name(run, metrics):
    """The bus the run used, from run.json or metrics.json."""
    b = first_of("bus", run)
    return b if b is not None else group(metrics, "bus").get("name")


def header_section(run_dir, run, metrics, metrics_problem):
    """Title, description, status banner and the run's identity/timing table."""
    run = run if isinstance(run, dict) else {}
    scenario = first_of("scenario", run, metrics) or os.path.basename(os.path.abspath(run_dir))
    rows = [
        ("scenario file", first_of("scenario_file", run, metrics)),
        ("bus", bus_name(run, metrics)),
        ("clock", first_of("clock", run, metrics)),
        ("model", run.get("model_variant") or group(metrics, "physics").get("model")),
        ("control period [s]", run.get("control_period_s")),
        ("physics timestep [s]", run.get("physics_timestep_s")),
        ("planned duration [s]", run.get("duration_s")),
        ("sim time [s]", first_of("sim_time_s", metrics)),
        ("wall time [s]", first_of("wall_time_s", metrics)),
        ("real-time factor", first_of("real_time_factor", metrics)),
    ]
    table = "".join(f"<tr><th>{esc(k)}</th>{cell(v)}</tr>" for k, v in rows if v is not None)
    desc = run.get("description")
    desc_html = f'<p class="desc">{esc(desc)}</p>' if desc else ""
    faults = run.get("faults") if isinstance(run.get("faults"), list) else []
    fault_html = ""
    if faults:
        items = "".join(f"<li>{esc(fault_label(f))}</li>" for f in faults if isinstance(f, dict))
        fault_html = f"<p>Faults (shaded on the time plots):</p><ul>{items}</ul>"
    return (f"<h1>Run report: {esc(scenario)}</h1>{desc_html}"
            f"{status_banner(metrics, metrics_problem)}<table>{table}</table>{fault_html}")


def fault_label(f):
    """One fault as text: what, where, when."""
    start = f.get("at_s", 0.0)
    dur = f.get("duration_s", 0.0)
    span = f"from {fmt_value(start)} s " + (f"for {fmt_value(dur)} s" if dur else "to the end")
    what = f.get("text") or f"{f.get('kind', '?')} {f.get('target', '')}".strip()
    return f"{what}, {span}"


def platform_table(metrics):
    """Truth and odometry pose errors side by side."""
    truth = group(metrics, "platform")
    odom = group(metrics, "platform_odometry") or None
    keys = [k for k in POSE_METRICS if k in truth] + sorted(
        k for k in truth if k not in POSE_METRICS)
    header = ["metric", "platform (MuJoCo truth)"] + (["master odometry"] if odom else [])
    rows = [[k, truth.get(k)] + ([odom.get(k)] if odom else []) for k in keys]
    return grid_table(header, rows)


def axes_table(metrics):
    """Per-axis velocity IAE and σ [encoder pulses per control period]."""
    axes = [a for a in metrics["axes"] if isinstance(a, dict)]
    keys = sorted({k for a in axes for k in a})
    return grid_table(["axis"] + keys, [[i + 1] + [a.get(k) for k in keys]
                                        for i, a in enumerate(axes)])


def metrics_section(metrics):
    """Every metric group of metrics.json as tables."""
    if metrics is None:
        return "<h2>Metrics</h2><p class=\"note\">metrics.json is absent: no metrics.</p>"
    parts = ["<h2>Metrics</h2>"]
    if isinstance(metrics.get("platform"), dict):
        parts += ["<h3>Platform pose errors</h3>", platform_table(metrics)]
    if isinstance(metrics.get("axes"), list) and metrics["axes"]:
        parts += ["<h3>Axes</h3>", axes_table(metrics)]
    for group, title in (("bus", "Bus"), ("drives", "Drives"), ("master", "Master"),
                         ("realtime", "Real-time pacing"), ("physics", "Physics")):
        if isinstance(metrics.get(group), dict):
            parts += [f"<h3>{title}</h3>", kv_table(metrics[group])]
    # Any other group (a newer metrics.json's) under its own name, and the run's own figures
    # that the header does not show (stopped_by, interrupted_phase …): nothing is left out.
    for group in sorted(k for k, v in metrics.items() if isinstance(v, dict) and k not in SHOWN_GROUPS):
        parts += [f"<h3>{esc(group)}</h3>", kv_table(metrics[group])]
    rest = {k: v for k, v in metrics.items()
            if not isinstance(v, (dict, list)) and k not in HEADER_SCALARS}
    if rest:
        parts += ["<h3>Run</h3>", kv_table(rest)]
    slaves = metrics.get("slaves") if isinstance(metrics.get("slaves"), list) else []
    slaves = [s for s in slaves if isinstance(s, dict)]
    if slaves:
        keys = sorted({k for s in slaves for k in s})
        parts += ["<h3>Slaves</h3>", grid_table(keys, [[s.get(k) for k in keys] for s in slaves])]
    return "".join(parts)


# ---------------------------------------------------------------------------------------
# Plots

def finite(series):
    """True when the series holds at least one finite value."""
    return any(math.isfinite(v) for v in series)


def decimated(cols, rows):
    """The columns thinned to at most MAX_PLOT_POINTS rows, keeping the last one."""
    if rows <= MAX_PLOT_POINTS:
        return cols
    step = math.ceil(rows / MAX_PLOT_POINTS)
    idx = list(range(0, rows, step))
    if idx[-1] != rows - 1:
        idx.append(rows - 1)
    return {k: [v[i] for i in idx] for k, v in cols.items()}


def fault_spans(run, t_end):
    """[(start, end)] of the run's faults [s]; a zero duration lasts to t_end."""
    spans = []
    faults = run.get("faults") if isinstance(run, dict) else None
    for f in faults if isinstance(faults, list) else []:
        start = number(f.get("at_s")) if isinstance(f, dict) else None
        if start is None:
            continue
        dur = number(f.get("duration_s")) or 0.0
        end = min(start + dur, t_end) if dur > 0 else t_end
        if start < t_end:  # one that begins after the run's end never happened
            spans.append((start, end))
    return spans


def shade_faults(ax, spans):
    """Shades the fault intervals on a time axis (one legend entry)."""
    for i, (a, b) in enumerate(spans):
        ax.axvspan(a, b, color=FAULT_COLOR, alpha=0.12, lw=0, label="fault" if i == 0 else None)


def save_png(fig, plots_dir, name):
    """Writes one PNG atomically (temp + rename) and closes the figure."""
    fig.tight_layout()
    final = os.path.join(plots_dir, name)
    temp = os.path.join(plots_dir, "." + name + ".part")
    fig.savefig(temp, format="png", dpi=PLOT_DPI)
    plt.close(fig)
    os.replace(temp, final)
    return name


def plot_path(c, plots_dir, goal_reached=True):
    """x-y path: reference, MuJoCo truth and odometry, equal aspect, start and goal marked.
    `goal_reached` False (metrics.json's path_done_s < 0): the plan stopped short of its goal,
    and its last point is marked as that, not as the goal."""
    if not (finite(c.get("x", [])) and finite(c.get("y", []))):
        return None
    fig, ax = plt.subplots(figsize=(7, 5.5))
    ref = finite(c.get("ref_x", [])) and finite(c.get("ref_y", []))
    if ref:
        ax.plot(c["ref_x"], c["ref_y"], "--", color="0.4", lw=1.2, label="reference")
    ax.plot(c["x"], c["y"], "-", color="tab:blue", lw=1.4, label="platform (truth)")
    if finite(c.get("odom_x", [])) and finite(c.get("odom_y", [])):
        ax.plot(c["odom_x"], c["odom_y"], ":", color="tab:orange", lw=1.2, label="odometry")
    sx, sy = (c["ref_x"], c["ref_y"]) if ref else (c["x"], c["y"])
    ax.plot(sx[0], sy[0], "o", color="tab:green", ms=8, label="start")
    ax.plot(sx[-1], sy[-1], "*", color="tab:red", ms=12,
            label="goal" if goal_reached else "end of the plan run (goal not reached)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("Path: platform vs reference")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    return save_png(fig, plots_dir, "path.png")


def pose_errors(c):
    """(ex, ey, contour) [cm] and phi error [deg] of the truth against the reference."""
    ex = [(a - b) * 100.0 for a, b in zip(c["x"], c["ref_x"])]
    ey = [(a - b) * 100.0 for a, b in zip(c["y"], c["ref_y"])]
    contour = [math.hypot(a, b) for a, b in zip(ex, ey)]
    ephi = [math.degrees(a - b) for a, b in zip(c.get("phi", []), c.get("ref_phi", []))]
    return ex, ey, contour, ephi


def plot_errors(c, plots_dir, spans):
    """Position errors ex, ey and contour error [cm], and phi error [deg], over time."""
    need = ("t", "x", "y", "ref_x", "ref_y")
    if not all(finite(c.get(k, [])) for k in need):
        return None
    ex, ey, contour, ephi = pose_errors(c)
    fig, (a, b) = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    a.plot(c["t"], ex, lw=1, label="e_x")
    a.plot(c["t"], ey, lw=1, label="e_y")
    a.plot(c["t"], contour, lw=1.3, color="k", label="contour |e|")
    a.set_ylabel("position error [cm]")
    a.set_title("Pose error: platform (truth) − reference")
    if finite(ephi):
        b.plot(c["t"], ephi, lw=1, color="tab:purple", label="e_phi")
    b.set_ylabel("heading error [deg]")
    b.set_xlabel("t [s]")
    for ax in (a, b):
        shade_faults(ax, spans)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    return save_png(fig, plots_dir, "errors.png")


def plot_wheels(c, plots_dir, spans):
    """Per wheel: measured speed, command and drive setpoint [rad/s] over time (NaN skipped)."""
    if not finite(c.get("t", [])):
        return None
    series = (("speed_rad_s", "measured", "-"), ("cmd_rad_s", "command", "--"),
              ("setpoint_rad_s", "drive setpoint", ":"))
    if not any(finite(c.get(f"w{i}_{s}", [])) for i in range(1, 5) for s, _, _ in series):
        return None
    fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True)
    for i, ax in enumerate(axes.flat, start=1):
        drawn = 0
        for suffix, label, style in series:
            col = c.get(f"w{i}_{suffix}", [])
            if finite(col):
                ax.plot(c["t"], col, style, lw=1, label=label)
                drawn += 1
        if not drawn:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        shade_faults(ax, spans)
        ax.set_title(f"wheel {i}")
        ax.set_ylabel("[rad/s]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    for ax in axes[1]:
        ax.set_xlabel("t [s]")
    return save_png(fig, plots_dir, "wheels.png")


def windowed_rates(t, counter):
    """(window edges, rates [1/s]) of a cumulative counter over windows of ~1 s.

    For a step plot with where="pre": rates[k] is the rate over (edges[k-1], edges[k]].
    """
    if len(t) < 2 or not (math.isfinite(t[0]) and math.isfinite(t[-1])) or t[-1] <= t[0]:
        return [], []
    span = t[-1] - t[0]
    window = 1.0 if span >= 5.0 else span / 10.0
    ends, rates = [t[0]], [math.nan]
    t0, c0, edge = t[0], counter[0], t[0] + window
    for ti, ci in zip(t, counter):
        if ti >= edge - 1e-9 and ti > t0:
            ends.append(ti)
            rates.append((ci - c0) / (ti - t0))
            t0, c0, edge = ti, ci, ti + window
    if t[-1] > t0:  # the last, partial window: the run's end is drawn too
        ends.append(t[-1])
        rates.append((counter[-1] - c0) / (t[-1] - t0))
    if len(rates) > 1:
        rates[0] = rates[1]  # the first window's rate drawn from its start
    return ends, rates


def plot_bus(bus, plots_dir, spans):
    """Bus statistics from bus.csv: frame rates, cumulative dropouts/errors, load, states."""
    t = bus.get("t", [])
    if not finite(t):
        return None
    states = [k for k in (f"s{i}_state" for i in range(1, 5)) if finite(bus.get(k, []))]
    n = 3 + (1 if states else 0)
    fig, axes = plt.subplots(n, 1, figsize=(9, 2.1 * n + 0.6), sharex=True)
    for key, label in (("frames_tx", "tx"), ("frames_rx", "rx")):
        if finite(bus.get(key, [])):
            ends, rates = windowed_rates(t, bus[key])
            axes[0].step(ends, rates, where="pre", lw=1, label=label)
    axes[0].set_ylim(bottom=0)
    axes[0].set_ylabel("frames [1/s]")
    axes[0].set_title("Bus statistics")
    for key in ("dropouts", "errors"):
        if finite(bus.get(key, [])):
            axes[1].plot(t, bus[key], lw=1, label=f"{key} (cumulative)")
    axes[1].set_ylim(bottom=0)
    axes[1].set_ylabel("count")
    if finite(bus.get("load", [])):
        axes[2].plot(t, bus["load"], lw=0.8, label="load")
    axes[2].set_ylabel("load [0…1]")
    if any(v > 0 for v in bus.get("active_faults", [])):
        right = axes[2].twinx()
        right.step(t, bus["active_faults"], where="post", lw=1, color="tab:red", alpha=0.7)
        right.set_ylabel("active faults", color="tab:red")
        right.yaxis.get_major_locator().set_params(integer=True)
    if states:
        for k in states:
            axes[3].step(t, bus[k], where="post", lw=1, label=k.split("_")[0])
        axes[3].set_yticks(range(len(DRIVE_STATES)), DRIVE_STATES, fontsize=7)
        axes[3].set_ylabel("drive state")
    axes[-1].set_xlabel("t [s]")
    for ax in axes:
        shade_faults(ax, spans)
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7, loc="best")
    return save_png(fig, plots_dir, "bus.png")


def run_end(run, traj, bus):
    """The last sim time the run recorded [s]; its planned duration when it recorded nothing.
    An interrupted run ends at its last sample: its plots must not run on to the planned
    end, nor shade faults that never began (found in review)."""
    t = [v for v in (traj.get("t") or bus.get("t") or []) if math.isfinite(v)]
    if t:
        return max(t)
    planned = run.get("duration_s") if isinstance(run, dict) else None
    return float(planned) if isinstance(planned, (int, float)) else 0.0


def make_plots(run_dir, run, traj, traj_rows, bus, bus_rows, bus_kind, metrics=None):
    """Draws every plot the data allows; ([(file, caption)], [notes]). Stale plots removed."""
    done = number(group(metrics, "platform").get("path_done_s")) if metrics else None
    goal_reached = done is None or done >= 0
    plots_dir = os.path.join(run_dir, "plots")
    os.makedirs(plots_dir, exist_ok=True)
    spans = fault_spans(run, run_end(run, traj, bus))
    c = decimated(traj, traj_rows)
    made = []
    if traj_rows:
        made = [(name, caption) for name, caption in (
            (plot_path(c, plots_dir, goal_reached), "Path vs reference"),
            (plot_errors(c, plots_dir, spans), "Pose errors over time"),
            (plot_wheels(c, plots_dir, spans), "Wheel speeds vs commands")) if name]
    notes = [f"{caption}: no trajectory data." for caption in TRAJECTORY_PLOTS
             if caption not in {m[1] for m in made}]
    if bus_rows and bus_kind != "direct":
        name = plot_bus(decimated(bus, bus_rows), plots_dir, spans)
        if name:
            made.append((name, "Bus statistics"))
    elif bus_kind == "direct":
        notes.append("Bus statistics: the direct bus has no frames (no bus plot).")
    else:
        notes.append("Bus statistics: bus.csv is absent or empty (no bus plot).")
    remove_stale(plots_dir, {m[0] for m in made})
    return made, notes


def remove_stale(plots_dir, keep):
    """Removes report plots of an earlier report that this one did not draw."""
    for name in PLOT_NAMES:
        path = os.path.join(plots_dir, name)
        if name not in keep and os.path.isfile(path):
            os.remove(path)


HEADLINE_PLOTS = 2  # the path and the pose errors: shown at the top of the page


def plots_section(made, notes, title="Plots"):
    """The plots as <img> elements referencing plots/*.png, with notes on missing ones."""
    parts = [f'<h2>{esc(title)}</h2><div class="plots">']
    for name, caption in made:
        parts.append(f'<h3>{esc(caption)}</h3><img src="plots/{href(name)}" alt="{esc(caption)}">')
    parts.append("</div>")
    parts += [f'<p class="note">{esc(n)}</p>' for n in notes]
    return "".join(parts)


def video_link(run_dir, video):
    """The run's video as a link relative to the report: `video` (run --video FILE, render
    --out FILE) or RUN_DIR/video.mp4; None when there is none."""
    path = video if video else os.path.join(run_dir, "video.mp4")
    if not os.path.isfile(path):
        return None
    return os.path.relpath(os.path.abspath(path), os.path.abspath(run_dir))


def video_section(run_dir, video=None, renderer=None):
    """The run's video right under the verdict, or nothing when it was not rendered;
    `renderer`: the GL that drew it, when the process that made it says so."""
    link = video_link(run_dir, video)
    if link is None:
        return ""
    drawn = f'<p class="note">Video drawn by {esc(renderer)}.</p>' if renderer else ""
    return f'<video controls preload="metadata" src="{href(link)}"></video>{drawn}'


def collapsible(html_text, open_=False):
    """A section folded under its own <h2> heading (HTML <details>, no script)."""
    m = re.match(r"<h2>(.*?)</h2>", html_text)
    if not m:
        return html_text
    state = " open" if open_ else ""
    return f"<details{state}><summary><h2>{m.group(1)}</h2></summary>{html_text[m.end():]}</details>"


# ---------------------------------------------------------------------------------------
# Events and files

def events_section(events, problem):
    """events.log as a table; fault, error and interrupt rows highlighted."""
    if problem:
        return f'<h2>Events</h2><p class="note">events.log is {esc(problem)}.</p>'
    rows = []
    for t, kind, msg in events[:MAX_EVENTS]:
        rows.append(f'<tr class="ev-{esc(kind)}"><td class="num">{esc(t)}</td>'
                    f"<td>{esc(kind)}</td><td>{esc(msg)}</td></tr>")
    more = (f'<p class="note">{len(events) - MAX_EVENTS} more events in events.log.</p>'
            if len(events) > MAX_EVENTS else "")
    return ("<h2>Events</h2><div class=\"scroll\"><table><tr><th>t [s]</th><th>kind</th>"
            f"<th>message</th></tr>{''.join(rows)}</table></div>{more}")


def expected_files(bus_kind, master_kind=None):
    """The files a complete run directory of this bus has (video aside)."""
    names = ["run.json", "trajectory.csv", "bus.csv", "events.log", "metrics.json"]
    wire = {"can": "can", "canopen": "can", "tml": "can", "ethercat": "ethercat", "m3": "m3"}.get(bus_kind)
    if wire:
        names.append(f"bus-{wire}.pcap")
    # A master the twin started writes master.log; the built-in one on these buses also its
    # counters. An external master (`omnitwin twin`) leaves neither here. run.json says which
    # (an older run.json does not: then only bus can's master.log is expected, as before).
    kind = master_kind if master_kind is not None else ("omni-master" if bus_kind == "can" else None)
    if wire and kind in ("omni-master", "command"):
        names.append("master.log")
    if kind == "omni-master" and bus_kind in ("canopen", "tml", "ethercat", "m3"):
        names.append("master-stats.json")
    return names


def files_section(run_dir, bus_kind, video=None, run=None):
    """Video (embedded when present) and links to the run's files that exist."""
    parts = ["<h2>Files</h2>"]
    pcaps = sorted(n for n in os.listdir(run_dir) if re.fullmatch(r"bus-[^/]+\.pcap", n))
    entries = [(video_link(run_dir, video) or "video.mp4", "H.264 video of the run")]
    entries += [(p, "bus capture (Wireshark, tshark)") for p in pcaps]
    entries += list(LINKED_FILES)
    items = []
    for name, what in entries:
        path = os.path.join(run_dir, name)
        if os.path.isfile(path):
            size = fmt_size(os.path.getsize(path))
            items.append(f'<li><a href="{href(name)}">{esc(name)}</a> ({esc(size)}): {esc(what)}</li>')
    parts.append(f"<ul>{''.join(items)}</ul>")
    master_kind = run.get("master_kind") if isinstance(run, dict) else None
    missing = [n for n in expected_files(bus_kind, master_kind)
               if not os.path.isfile(os.path.join(run_dir, n))]
    if video_link(run_dir, video) is None:
        missing.append("video.mp4 (not rendered: --no-video, or `omnitwin render` not run yet)")
    if missing:
        parts.append('<p class="note">Absent: ' + esc(", ".join(missing)) + ".</p>")
    return "".join(parts)


# ---------------------------------------------------------------------------------------
# The page

def write_atomic(path, text):
    """Writes text to path through a temporary file and a rename."""
    temp = os.path.join(os.path.dirname(path), "." + os.path.basename(path) + ".part")
    with open(temp, "w", encoding="utf-8") as f:
        f.write(text)
    os.replace(temp, path)


def data_notes(traj_problem, traj_rows, bus_problem, run_problem):
    """Notes on the state of the run's data files."""
    notes = []
    if run_problem == "absent":
        notes.append("run.json is absent (an older run directory): no description, faults or bounds.")
    elif run_problem:
        notes.append(f"run.json is {run_problem}.")
    if traj_problem:
        notes.append(f"trajectory.csv: {traj_problem}.")
    elif traj_rows == 0:
        notes.append("trajectory.csv holds no rows.")
    if bus_problem and bus_problem != "absent":
        notes.append(f"bus.csv: {bus_problem}.")
    return notes


def build_report(run_dir, video=None, renderer=None):
    """Reads the run directory, draws the plots and writes report.html; returns its path.
    `video`: the run's video when it is not RUN_DIR/video.mp4; `renderer`: the GL that drew
    it (said under the video)."""
    run, run_problem = load_json(os.path.join(run_dir, "run.json"))
    run = run if isinstance(run, dict) else None
    metrics, metrics_problem = load_json(os.path.join(run_dir, "metrics.json"))
    if metrics is not None and not isinstance(metrics, dict):
        metrics, metrics_problem = None, "not a JSON object"
    traj, traj_rows, traj_problem = read_table(os.path.join(run_dir, "trajectory.csv"))
    bus, bus_rows, bus_problem = read_table(os.path.join(run_dir, "bus.csv"))
    events, events_problem = read_events(os.path.join(run_dir, "events.log"))
    bus_kind = bus_name(run, metrics)
    made, plot_notes = make_plots(run_dir, run, traj, traj_rows, bus, bus_rows, bus_kind, metrics)
    notes = data_notes(traj_problem, traj_rows, bus_problem, run_problem)
    title = first_of("scenario", run, metrics) or os.path.basename(os.path.abspath(run_dir))
    # What a person wants first: the verdict, the video, the headline plots and the
    # expectations; the detailed tables below, folded.
    body = [header_section(run_dir, run, metrics, metrics_problem),
            "".join(f'<p class="note">{esc(n)}</p>' for n in notes),
            video_section(run_dir, video, renderer),
            plots_section(made[:HEADLINE_PLOTS], [], "At a glance"),
            expectations_section(run, metrics),
            collapsible(metrics_section(metrics)),
            collapsible(plots_section(made[HEADLINE_PLOTS:], plot_notes, "More plots"), open_=True),
            collapsible(events_section(events, events_problem)),
            collapsible(files_section(run_dir, bus_kind, video, run), open_=True)]
    page = ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>omnitwin run: {esc(title)}</title><style>{CSS}</style></head>\n<body>\n"
            + "\n".join(body) + "\n</body></html>\n")
    out = os.path.join(run_dir, "report.html")
    write_atomic(out, page)
    return out


def usage_error(message):
    """One line on stderr, exit 2."""
    sys.stderr.write(f"run_report.py: {message}\n")
    sys.exit(2)


def main(argv):
    """Entry point: run_report.py RUN_DIR [--video FILE] [--renderer TEXT]."""
    usage = "usage: run_report.py RUN_DIR [--video FILE] [--renderer TEXT]"
    if len(argv) < 2 or len(argv) % 2 != 0:
        usage_error(usage)
    options = {}
    for flag, value in zip(argv[2::2], argv[3::2]):
        if flag not in ("--video", "--renderer") or flag in options:
            usage_error(usage)
        options[flag] = value
    video, renderer = options.get("--video"), options.get("--renderer")
    run_dir = argv[1]
    if not os.path.isdir(run_dir):
        usage_error(f"'{run_dir}' is not a directory")
    if not any(os.path.isfile(os.path.join(run_dir, n)) for n in RUN_FILES):
        usage_error(f"'{run_dir}' is not a run directory (none of {', '.join(RUN_FILES)})")
    try:
        out = build_report(run_dir, video, renderer)
    except OSError as e:
        sys.stderr.write(f"run_report.py: cannot write the report in '{run_dir}': {e}\n")
        sys.exit(3)
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
