"""What a batch folder says to a person: DIR/index.html (a sortable table of every job, the line delay
per camera mode with error bars, links to each job's report and log) and the text of `--status`."""
from __future__ import annotations

import html
import os
import socket
from pathlib import Path

from .store import (
    ANSWERED,
    BAD_INPUT,
    INTERRUPTED,
    NOT_ANSWERED,
    NOT_TRUSTED,
    OK,
    QUEUED,
    RUNNING,
    UNDETERMINED,
    ResultStore,
    driver_running,
)

INDEX_FILE = "index.html"
PLOT_FILE = "line_delay_by_mode.png"
NO_MODE = "(no mode)"


def format_value(row: dict) -> str:
    """The headline number with its sigma, in the unit people read it in."""
    value, std = row.get("value"), row.get("value_std")
    if value is None:
        return ""
    if row.get("value_name") == "line_delay_s":
        text, unit, scale = "d = ", " µs/row", 1e6
    else:
        text, unit, scale = f"{(row.get('value_name') or '').replace('_px', '')} = ", " px", 1.0
    sigma = f" ± {std * scale:.4g}" if std is not None else ""
    return f"{text}{value * scale:.6g}{sigma}{unit}"


# the index's number columns, one unit each: (value_name, scale from the stored SI value, header)
# (intrinsics' fx and selfcalib's f share the focal-length columns)
_NUMBER_COLUMNS = ((("line_delay_s",), 1e6, "line delay (µs/row)"), (("line_delay_s",), 1e6, "σ line delay (µs/row)"),
                   (("f_px", "fx_px"), 1.0, "f (px)"), (("f_px", "fx_px"), 1.0, "σ f (px)"))


def _number_cells(row: dict) -> list:
    """The headline number and its sigma in the columns of their quantity (blank in the others)."""
    cells = []
    for k, (names, scale, _) in enumerate(_NUMBER_COLUMNS):
        value = row.get("value" if k % 2 == 0 else "value_std") if row.get("value_name") in names else None
        cells.append(_cell("", "") if value is None else _cell(f"{value * scale:.6g}" if k % 2 == 0
                                                                else f"{value * scale:.3g}", repr(value)))
    return cells


def _plotted(row: dict) -> bool:
    """Line delays that the job claims (undetermined runs claim no number)."""
    return row.get("value_name") == "line_delay_s" and row.get("value") is not None and row["status"] in (OK, NOT_TRUSTED)


def plot_line_delay_by_mode(rows: list, path: Path) -> bool:
    """Each job's line delay with its 1-sigma bar, one column per camera mode; False if none to plot."""
    rows = [r for r in rows if _plotted(r)]
    if not rows:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    modes = sorted({r["mode"] or NO_MODE for r in rows})
    fig, ax = plt.subplots(figsize=(max(5.0, 1.2 * len(modes) + 2), 4.0))
    for x, mode in enumerate(modes):
        group = [r for r in rows if (r["mode"] or NO_MODE) == mode]
        for k, r in enumerate(group):  # spread the jobs of a mode across its column
            offset = (k - (len(group) - 1) / 2) * min(0.6 / max(len(group), 1), 0.12)
            trusted = r["status"] == OK
            ax.errorbar(x + offset, r["value"] * 1e6, yerr=(r["value_std"] or 0) * 1e6,
                        fmt="o" if r["command"] == "linedelay" else "s", ms=4, capsize=2,
                        color="tab:blue" if trusted else "tab:orange")
    ax.set_xticks(range(len(modes)))
    ax.set_xticklabels(modes, rotation=30 if len(modes) > 4 else 0, ha="right" if len(modes) > 4 else "center")
    ax.set_ylabel("line delay (µs/row), ±1σ")
    ax.set_title("Line delay per camera mode", fontsize=11)
    key = [ax.errorbar([], [], yerr=[], fmt=fmt, ms=4, color=color, label=label)
           for fmt, color, label in (("o", "tab:blue", "linedelay, trusted"), ("o", "tab:orange", "not trusted"),
                                     ("s", "tab:blue", "flicker"))]
    ax.legend(handles=key, fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


_SORT_SCRIPT = """
document.querySelectorAll('th').forEach((th, col) => th.addEventListener('click', () => {
  const body = th.closest('table').tBodies[0];
  const up = th.dataset.dir !== 'up'; th.dataset.dir = up ? 'up' : 'down';
  const key = td => { const v = td.dataset.sort ?? td.textContent; const n = parseFloat(v);
                      return isNaN(n) || v.trim() === '' ? v.toLowerCase() : n; };
  [...body.rows].sort((a, b) => { const x = key(a.cells[col]), y = key(b.cells[col]);
      if (typeof x !== typeof y) return (typeof x === 'number' ? -1 : 1) * (up ? 1 : -1);
      return (x < y ? -1 : x > y ? 1 : 0) * (up ? 1 : -1); }).forEach(r => body.appendChild(r));
}));
"""


def _cell(text, sort=None) -> str:
    attr = f' data-sort="{html.escape(str(sort))}"' if sort is not None else ""
    return f"<td{attr}>{text}</td>"


def _link(out: Path, relative, label: str) -> str:
    if relative and (out / relative).exists():
        return f'<a href="{html.escape(str(relative))}">{label}</a>'
    return ""


def write_index(out_dir, rows: list) -> Path:
    """DIR/index.html (and the plot next to it) from the store's rows."""
    out = Path(out_dir)
    has_plot = plot_line_delay_by_mode(rows, out / PLOT_FILE)
    counts = status_counts(rows)
    table = []
    for r in rows:
        job_dir = r.get("out_dir") or f"jobs/{r['id']}"
        report = _link(out, f"{job_dir}/report.html", "report") or _link(out, f"{job_dir}/result.json", "result.json")
        table.append("<tr>" + "".join([
            _cell(html.escape(r["id"])), _cell(html.escape(r.get("mode") or "")), _cell(html.escape(r.get("command") or "")),
            _cell(html.escape(r["status"] or "")), _cell("" if r.get("exit_code") is None else r["exit_code"]),
            *_number_cells(r),
            _cell(html.escape(r.get("verdict") or "")), _cell(html.escape(r.get("reason") or "")),
            _cell("" if r.get("wall_time_s") is None else f"{r['wall_time_s']:.1f}", r.get("wall_time_s") or ""),
            _cell("" if r.get("cpu_time_s") is None else f"{r['cpu_time_s']:.1f}", r.get("cpu_time_s") or ""),
            _cell("" if r.get("peak_memory_mb") is None else f"{r['peak_memory_mb']:.0f}", r.get("peak_memory_mb") or ""),
            _cell(f"{report} {_link(out, r.get('log_path'), 'log')}"),
        ]) + "</tr>")
    headers = ["job", "mode", "command", "status", "exit", *(h for _, _, h in _NUMBER_COLUMNS), "verdict", "reason",
               "wall time (s)", "CPU (s)", "peak memory (MB)", "files"]
    page = f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>rscalib batch: {html.escape(out.name)}</title>
<style>body{{font-family:sans-serif;margin:1.5em}} table{{border-collapse:collapse;font-size:90%}}
td,th{{border:1px solid #ccc;padding:3px 6px;text-align:left}} th{{cursor:pointer;background:#eee}}</style></head>
<body><h1>rscalib batch</h1>
<p>{html.escape(summary_line(counts))}. Click a column header to sort. The results store is
<code>results.sqlite</code> (one row per job); <code>rscalib batch --status {html.escape(str(out))}</code> prints progress.</p>
{f'<img src="{PLOT_FILE}" alt="line delay per camera mode">' if has_plot else '<p>No line delay to plot yet.</p>'}
<table><thead><tr>{''.join(f'<th>{h}</th>' for h in headers)}</tr></thead>
<tbody>
{chr(10).join(table)}
</tbody></table>
<script>{_SORT_SCRIPT}</script>
</body></html>
"""
    path = out / INDEX_FILE
    tmp = out / f".{INDEX_FILE}.{os.getpid()}.tmp"
    tmp.write_text(page)
    os.replace(tmp, path)
    return path


def status_counts(rows: list) -> dict:
    counts = {}
    for r in rows:
        counts[r["status"]] = counts.get(r["status"], 0) + 1
    return counts


def summary_line(counts: dict) -> str:
    """'14 jobs: done 11 (ok 7, ...), running 1, queued 0, failed 2 (...)'."""
    def part(statuses) -> str:
        inner = ", ".join(f"{s} {counts[s]}" for s in statuses if counts.get(s))
        return f" ({inner})" if inner else ""

    done = sum(counts.get(s, 0) for s in ANSWERED)
    failed = sum(counts.get(s, 0) for s in NOT_ANSWERED)
    total = sum(counts.values())
    interrupted = f", interrupted {counts[INTERRUPTED]}" if counts.get(INTERRUPTED) else ""
    return (f"{total} jobs: done {done}{part((OK, NOT_TRUSTED, UNDETERMINED, BAD_INPUT))}, "
            f"running {counts.get(RUNNING, 0)}, queued {counts.get(QUEUED, 0)}{interrupted}, "
            f"failed {failed}{part(NOT_ANSWERED)}")


def _driver_alive(out: Path, meta: dict) -> bool:
    """Whether the batch's driver is running: it holds DIR's lock (store.driver_lock; the kernel
    drops it when the driver dies, however); for a batch of an older rscalib, its pid."""
    held = driver_running(out)
    if held is not None:
        return held
    if meta.get("driver_host") != socket.gethostname():
        return meta.get("state") == "running"  # another machine: trust what it wrote
    try:
        os.kill(int(meta.get("driver_pid")), 0)
        return True
    except (OSError, TypeError, ValueError):
        return False


def status_lines(out_dir) -> list:
    """`rscalib batch --status DIR`: progress, whether the batch is still running, what failed and why.

    Reads only (the store is opened read-only, no lock is taken that a driver would wait for), so
    it works on a read-only copy and changes nothing, whatever the folder holds: a file that is not
    an rscalib store is an InputError. A job queued or running when its driver is gone (killed,
    however) is shown as interrupted: nothing is running it; --resume does."""
    out = Path(out_dir)
    from .store import STORE_FILE

    store = ResultStore(out / STORE_FILE, read_only=True)
    try:
        rows, meta = store.rows(), store.meta()
    finally:
        store.close()
    state = meta.get("state", "unknown")
    alive = _driver_alive(out, meta)
    if state == "running" and not alive:
        state = "stopped"
    if not alive:
        rows = [{**r, "status": INTERRUPTED} if r["status"] in (RUNNING, QUEUED) else r for r in rows]
    counts = status_counts(rows)
    lines = [f"{out}: {summary_line(counts)}"]
    if state == "running":
        lines.append(f"the batch is running (pid {meta.get('driver_pid')} on {meta.get('driver_host')}, "
                     f"since {meta.get('started_utc')})")
    elif state in ("stopped", "interrupted"):
        lines.append(f"the batch {'was interrupted' if state == 'interrupted' else 'stopped without finishing'} "
                     f"(its driver is gone; {counts.get(INTERRUPTED, 0)} jobs interrupted): --resume runs what is "
                     "missing")
    else:
        lines.append(f"the batch finished at {meta.get('finished_utc')}; {out / INDEX_FILE}")
    for r in rows:
        if r["status"] in NOT_ANSWERED or r["status"] == BAD_INPUT:
            lines.append(f"  {r['id']}: {r['status']}: {r.get('reason') or ''}")
        elif r["status"] == RUNNING and state == "running":
            lines.append(f"  {r['id']}: running on {r.get('worker')} since {r.get('started_utc')}")
        elif r["status"] == INTERRUPTED:
            lines.append(f"  {r['id']}: interrupted (its driver is gone){' on ' + r['worker'] if r.get('worker') else ''}")
    return lines
