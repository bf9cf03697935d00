"""What the run report and the check index share (media/report): reading metrics.json.

No matplotlib here, so the index page can be written without it.
"""


def metric_at(metrics, path):
    """(found, value) for a dotted metric path: objects by key, arrays by index."""
    cur = metrics
    for part in path.split("."):
        if isinstance(cur, dict) and part in cur:
            cur = cur[part]
        elif isinstance(cur, list) and part.isdigit() and int(part) < len(cur):
            cur = cur[int(part)]
        else:
            return False, None
    return True, cur
