"""The report.html every command writes: one self-contained page (plots embedded), the verdict
first, then the result, the plots each with a sentence on what to look for, the files and the
provenance. The commands' report modules fill the sections; this module owns the page."""
from __future__ import annotations

import base64
import html
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Optional

from .cameras import FILE_PURPOSES

_STYLE = """body{{font-family:sans-serif;max-width:1000px;margin:2em auto;color:#222;line-height:1.35}}
table{{border-collapse:collapse}}th,td{{padding:3px 10px;border-bottom:1px solid #ddd;text-align:left;vertical-align:top}}
.verdict{{border-left:6px solid {colour};padding:0.5em 1em;background:#f6f6f6}}
figure{{margin:1.5em 0}}img{{max-width:100%}}figcaption{{color:#444;font-size:92%}}
.look{{color:#555}} details{{margin:1em 0}}"""
_COLOURS = {"trusted": "#1a7f37", "not trusted": "#b35900", "not determined": "#8a1c1c"}


@dataclass
class Figure:
    """A plot of the report: the PNG, its title and one sentence on what to look for."""

    path: Path
    title: str
    look_for: str = ""


def escape(value) -> str:
    return html.escape(str(value))


def embedded_image(path: Path, alt: str) -> str:
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    return f'<img src="data:image/png;base64,{data}" alt="{escape(alt)}">'


def figure_html(figure: Figure) -> str:
    look = f' <span class="look">{escape(figure.look_for)}</span>' if figure.look_for else ""
    return (f"<figure>{embedded_image(figure.path, figure.title)}<figcaption><strong>{escape(figure.title)}."
            f"</strong>{look}</figcaption></figure>")


def table_html(rows: Iterable[tuple], header: Optional[tuple] = None) -> str:
    """Rows of (label, value[, ...]); the first cell of each row is its heading."""
    head = "" if header is None else "<tr>" + "".join(f"<th>{escape(h)}</th>" for h in header) + "</tr>"
    body = "".join("<tr><th>" + escape(row[0]) + "</th>" + "".join(f"<td>{escape(c)}</td>" for c in row[1:])
                   + "</tr>" for row in rows if row[1] is not None)
    return f"<table>{head}{body}</table>"


def list_html(items: Iterable[str]) -> str:
    items = list(items)
    return "<ul>" + "".join(f"<li>{escape(i)}</li>" for i in items) + "</ul>" if items else ""


def verdict_html(verdict, advice_line: str = "") -> str:
    """The verdict box: the headline, the reasons, and (unless trusted) where to learn what to do."""
    reasons = list_html(verdict.reasons)
    after = "" if verdict.trusted or not advice_line else f"<p>{escape(advice_line)}</p>"
    return (f'<div class="verdict"><p><strong>{escape(verdict.status)}:</strong> {escape(verdict.headline)}</p>'
            f"{reasons}{after}</div>")


def files_html(files: dict) -> str:
    """The files a run wrote, each a link with one line on what it is for (io.cameras.FILE_PURPOSES)."""
    items = [("result.json", FILE_PURPOSES["result_json"])]
    for role, name in files.items():
        if role in FILE_PURPOSES and isinstance(name, str) and role != "report":
            items.append((name, FILE_PURPOSES[role]))
    for name in files.get("plots", []):
        items.append((name, "a plot shown above"))
    return "<ul>" + "".join(f'<li><a href="{escape(n)}">{escape(n)}</a>: {escape(what)}</li>'
                            for n, what in items) + "</ul>"


def provenance_html(provenance: dict) -> str:
    """Which rscalib, command line, input files (with SHA-256), camera and target as read."""
    rows = [("rscalib", provenance.get("rscalib_version")), ("command line", provenance.get("command_line")),
            ("created (UTC)", provenance.get("created_utc"))]
    for role, record in (provenance.get("input_files") or {}).items():
        for r in record if isinstance(record, list) else [record]:
            count = f", {r['files']} files" if "files" in r else ""
            rows.append((f"input: {role}", f"{r['path']} ({r['bytes']} bytes{count}; sha256 {r['sha256'][:16]}…)"))
    for name, value in (provenance.get("inputs") or {}).items():   # settings recorded with the inputs
        if name not in (provenance.get("input_files") or {}) and value is not None:
            rows.append((f"input: {name}", value))
    camera = provenance.get("camera_as_read")
    if camera and "model" in camera:
        values = ", ".join(f"{n} {v:.6g}" for n, v in zip(camera["param_names"], camera["params"]))
        rows.append(("camera as read", f"{camera['model']} {camera['width']}x{camera['height']} from a "
                                       f"{camera['format']} file: {values}"))
    target = provenance.get("target_as_read")
    if target and "target_type" in target:
        rows.append(("target as read", ", ".join(f"{k} {v}" for k, v in target.items())))
    if provenance.get("rows") is not None:
        rows.append(("rows read out", provenance["rows"]))
    return table_html(rows)


def write_report(path: Path, title: str, verdict, sections: list, *, files: Optional[dict] = None,
                 provenance: Optional[dict] = None, advice_line: str = "", appendix: str = "") -> None:
    """The page: title, the verdict, the sections (HTML strings, in order), the files, the
    provenance and an appendix (folded: the expert's plots and numbers)."""
    colour = _COLOURS.get(verdict.status, "#555")
    body = "\n".join(s for s in sections if s)
    files_part = "" if files is None else f"<h2>Files</h2>{files_html(files)}"
    extra = f"<details><summary>Appendix: for the expert</summary>{appendix}</details>" if appendix else ""
    Path(path).write_text(f"""<!doctype html><html><head><meta charset="utf-8"><title>{escape(title)}</title>
<style>{_STYLE.format(colour=colour)}</style></head><body>
<h1>{escape(title)}</h1>
{verdict_html(verdict, advice_line)}
{body}
{files_part}
{extra}
<h2>Provenance</h2>{provenance_html(provenance or {})}
</body></html>""")
