#!/usr/bin/python3
"""media layer — the index page of `omnitwin check`: one row per scenario it ran.

Called as `check_index.py OUT_HTML SUMMARY_JSON` (by media/run_report.cpp). SUMMARY_JSON is
{"title": str, "results": [{"scenario", "file", "run_dir", "exit_code", "passed",
"failures": [str], "metrics": {...}}]}; `metrics` may be nested as in metrics.json or hold
flat dotted keys ("platform.final_error_cm"). The page shows the totals ("N passed, N
failed"), each scenario's status and key metrics, and links to each run's report.html
relative to OUT_HTML's folder, so the whole output tree can be moved or archived.

Self-contained HTML+CSS, no JavaScript, no timestamps (deterministic for the same input),
written to a temporary name and renamed. Stdlib only. Exit 0 on success, 2 on bad usage or
an invalid summary, 3 when the page cannot be written.
"""
import html
import json
import math
import os
import sys
import urllib.parse

from report_common import metric_at  # the same dotted-path rule as the run report

# Key metric columns: (heading, dotted metric path).
KEY_METRICS = (
    ("final error [cm]", "platform.final_error_cm"),
    ("IAE contour [cm]", "platform.iae_contour_cm"),
    ("RTF", "real_time_factor"),
    ("bus", "bus.name"),
    ("dropouts", "bus.dropouts"),
)
CSS = """
body{font-family:sans-serif;margin:1.5em auto;max-width:1200px;color:#222;padding:0 1em}
.totals{font-size:1.4em;font-weight:bold;padding:.5em .8em;border-radius:6px;margin:.8em 0}
.totals.pass{background:#dff3df;color:#14591a;border:2px solid #2e8b37}
.totals.fail{background:#fbe0e0;color:#8a1111;border:2px solid #c62828}
table{border-collapse:collapse;font-size:.92em}
th,td{border:1px solid #ccc;padding:.25em .6em;text-align:left;vertical-align:top}
th{background:#f2f2f2}td.num{text-align:right;font-family:monospace}
td.PASS{background:#dff3df;color:#14591a;font-weight:bold}
td.FAIL,td.ERROR{background:#fbe0e0;color:#8a1111;font-weight:bold}
ul{margin:0;padding-left:1.2em}.muted{color:#777}
"""


def esc(text):
    """HTML-escaped text of anything."""
    return html.escape(str(text), quote=True)


def metric(metrics, path):
    """A metric by flat dotted key or nested path (arrays by index); None if absent."""
    if not isinstance(metrics, dict):
        return None
    if path in metrics:
        return metrics[path]
    found, value = metric_at(metrics, path)
    return value if found else None


def fmt_value(v):
    """A value for a table cell: floats with 4 significant digits, None as a dash."""
    if v is None:
        return "—"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{v:.4g}" if math.isfinite(v) else str(v)
    return str(v)


def status_of(result):
    """PASS, FAIL (expectations not met) or ERROR (the run could not be done or finished)."""
    if result.get("passed") is True:
        return "PASS"
    code = result.get("exit_code")
    return "ERROR" if isinstance(code, int) and code >= 2 else "FAIL"


def report_link(result, index_dir):
    """The <a> to the run's report.html relative to the index, or a note why there is none."""
    run_dir = result.get("run_dir")
    name = esc(result.get("scenario") or "?")
    if not isinstance(run_dir, str) or not run_dir:
        return f'{name} <span class="muted">(no run directory)</span>'
    report = os.path.join(os.path.abspath(run_dir), "report.html")
    if not os.path.isfile(report):
        return f'{name} <span class="muted">(no report)</span>'
    rel = os.path.relpath(report, index_dir)
    return f'<a href="{esc(urllib.parse.quote(rel))}">{name}</a>'


def result_row(result, index_dir):
    """One table row: status, scenario (linked), file, key metrics, exit code, failures."""
    status = status_of(result)
    metrics = result.get("metrics")
    cells = [f'<td class="{status}">{status}</td>', f"<td>{report_link(result, index_dir)}</td>",
             f"<td>{esc(result.get('file') or '—')}</td>"]
    for _, path in KEY_METRICS:
        v = metric(metrics, path)
        num = isinstance(v, (int, float)) and not isinstance(v, bool)
        attr = ' class="num"' if num else ""
        cells.append(f"<td{attr}>{esc(fmt_value(v))}</td>")
    cells.append(f'<td class="num">{esc(fmt_value(result.get("exit_code")))}</td>')
    failures = result.get("failures") if isinstance(result.get("failures"), list) else []
    items = "".join(f"<li>{esc(f)}</li>" for f in failures)
    cells.append(f"<td><ul>{items}</ul></td>" if items else "<td></td>")
    return "<tr>" + "".join(cells) + "</tr>"


def build_page(summary, index_dir):
    """The whole index page as text."""
    title = summary.get("title") or "omnitwin check"
    results = [r for r in summary["results"] if isinstance(r, dict)]
    passed = sum(1 for r in results if status_of(r) == "PASS")
    failed = len(results) - passed
    errors = sum(1 for r in results if status_of(r) == "ERROR")
    could_not_run = f" ({errors} of them could not run)" if errors else ""
    head = "".join(f"<th>{esc(h)}</th>" for h in
                   ["status", "scenario", "file"] + [k for k, _ in KEY_METRICS]
                   + ["exit", "failures"])
    rows = "".join(result_row(r, index_dir) for r in results)
    cls = "pass" if failed == 0 else "fail"
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{esc(title)}</title><style>{CSS}</style></head>\n<body>\n"
            f"<h1>{esc(title)}</h1>\n<div class=\"totals {cls}\">{passed} passed, {failed} failed"
            f"{could_not_run}</div>\n<table><tr>{head}</tr>\n{rows}</table>\n</body></html>\n")


def write_atomic(path, text):
    """Writes text to path through a temporary file and a rename."""
    temp = os.path.join(os.path.dirname(path) or ".", "." + os.path.basename(path) + ".part")
    with open(temp, "w", encoding="utf-8") as f:
        f.write(text)
    os.replace(temp, path)


def fail(code, message):
    """One line on stderr, then exit with `code`."""
    sys.stderr.write(f"check_index.py: {message}\n")
    sys.exit(code)


def load_summary(path):
    """The summary JSON, checked to be an object with a `results` list (exit 2 if not)."""
    try:
        with open(path, encoding="utf-8") as f:
            summary = json.load(f)
    except OSError as e:
        fail(2, f"cannot read '{path}': {e.strerror}")
    except ValueError as e:
        fail(2, f"'{path}' is not valid JSON: {e}")
    if not isinstance(summary, dict) or not isinstance(summary.get("results"), list):
        fail(2, f"'{path}': expected an object with a 'results' list")
    return summary


def main(argv):
    """Entry point: check_index.py OUT_HTML SUMMARY_JSON."""
    if len(argv) != 3:
        fail(2, "usage: check_index.py OUT_HTML SUMMARY_JSON")
    out_html = os.path.abspath(argv[1])
    summary = load_summary(argv[2])
    index_dir = os.path.dirname(out_html)
    try:
        os.makedirs(index_dir, exist_ok=True)
        write_atomic(out_html, build_page(summary, index_dir))
    except OSError as e:
        fail(3, f"cannot write '{out_html}': {e}")
    print(out_html)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
