"""The report shell: one page style, figure embedding and tables with units for every HTML report.

The maintenance report (:mod:`hil.report.maint`), the BLFserv report
(:mod:`hil.report.serv`) and the diagnosis report (:mod:`hil.report.diagnose`)
are self-contained HTML files (figures embedded as PNG data URIs) built from
these pieces, so they look alike and a change of style is made once.
matplotlib is imported only when a figure is drawn (never in the cyclic loop
of ``emacheck run``).
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

CSS = """body{font-family:sans-serif;max-width:1300px;margin:1em auto;color:#222;line-height:1.35}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}
th{background:#eee}td:first-child,th:first-child{text-align:left}img{max-width:100%}
.pass{color:#070}.fail{color:#b00}.aborted,.incomplete{color:#b60}.warn{color:#b60}
details{margin:1em 0}summary{cursor:pointer;color:#555}pre{font-size:85%;background:#f6f6f6;padding:.5em}
small{color:#555}"""


def pyplot():
    """matplotlib's pyplot on the Agg backend (no display), imported on first use."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def figure_uri(fig: Any, *, dpi: int = 80, tight: bool = False) -> str:
    """PNG data URI of a laid-out matplotlib figure; closes the figure.

    ``tight`` crops to the drawn area (``bbox_inches="tight"``).
    """
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, **({"bbox_inches": "tight"} if tight else {}))
    pyplot().close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def img(fig: Any, *, dpi: int = 80, tight: bool = False) -> str:
    """An ``<img>`` element showing ``fig`` (see :func:`figure_uri`)."""
    return f"<img src='{figure_uri(fig, dpi=dpi, tight=tight)}'>"


def thin(n: int, max_points: int = 6000) -> slice:
    """Every k-th of ``n`` samples so that a plot gets at most about ``max_points`` of them."""
    return slice(None, None, max(1, n // max_points))


def fmt(x: float | None, nd: int = 4) -> str:
    """A number with ``nd`` decimals, "—" for None."""
    return "—" if x is None else f"{x:.{nd}f}"


def esc(text: object) -> str:
    """HTML-escaped text."""
    return html.escape(str(text))


def column(name: str, unit: str | None = None) -> str:
    """A column heading with its unit: ``backlash [mm]``."""
    return f"{name} [{unit}]" if unit else name


def table(columns: Sequence[str], rows: Iterable[Sequence[object]], *, raw: bool = False) -> str:
    """An HTML table; ``columns`` as from :func:`column`, cells escaped unless ``raw``."""
    cell = (lambda c: str(c)) if raw else esc
    head = "".join(f"<th>{esc(c)}</th>" for c in columns)
    body = "".join("<tr>" + "".join(f"<td>{cell(c)}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def notes(items: Iterable[str], *, css: str = "warn") -> str:
    """One paragraph per note."""
    return "".join(f"<p class='{css}'><b>note:</b> {esc(n)}</p>" for n in items)


def file_link(name: str, what: str = "the machine-readable result") -> str:
    """A paragraph linking a file written next to the report (relative link)."""
    return f"<p>{esc(what).capitalize()}: <a href='{esc(name)}'>{esc(name)}</a></p>"


def trace_lines(trace: dict | None) -> str:
    """The traceability block of a report: when, what software, which actuators, who, for what work order."""
    if not trace:
        return ""
    rows = [["started (UTC)", trace.get("started_utc") or "—"], ["analysed (UTC)", trace.get("analysed_utc") or "—"],
            ["software", f"{trace.get('software', {}).get('name', '')} {trace.get('software', {}).get('version', '')}"],
            ["operator", trace.get("operator") or "—"], ["work order", trace.get("work_order") or "—"],
            ["run id", trace.get("run_id") or "—"]]
    for k, ident in (trace.get("identity") or {}).items():
        if ident:
            rows.append([f"{k} identity (0x1018)",
                         f"vendor 0x{ident.get('vendor_id', 0):08X}, product 0x{ident.get('product_code', 0):08X}, "
                         f"revision 0x{ident.get('revision', 0):08X}, serial {ident.get('serial', '—')}"])
    for k, ml in (trace.get("master_loss") or {}).items():
        rows.append([f"{k} reaction to losing the master", master_loss_text(ml)])
    for k, fc in (trace.get("force_control") or {}).items():
        rows.append([f"{k} holds forces by", "its CST mode (target torque)" if fc == "cst" else
                     "the master's force loop on the measured force in CSP (its drive has no CST)"])
    for k, h in (trace.get("files_sha256") or {}).items():
        rows.append([f"{k} (sha256)", h[:16] + "…" if h else "—"])
    return "<h2>Traceability</h2>" + identity_warning(trace.get("identity")) + table(["item", "value"], rows)


def identity_warning(identity: dict | None) -> str:
    """A line saying so where EMA 1 and EMA 2 report one serial number (hil.runrecord.shared_serial);
    empty otherwise."""
    from hil.runrecord import shared_serial

    clash = shared_serial(identity)
    return "" if clash is None else f"<p class='fail'><b>Identity:</b> {esc(clash)}.</p>"


def master_loss_text(ml: dict) -> str:
    """What the record says of a drive's reaction to the master's death: configured (written and read back)
    and what the drill observed, each said for what it is."""
    if ml.get("configured"):
        text = (f"configured: consumer heartbeat {ml.get('consumer_heartbeat_ms')} ms on node "
                f"{ml.get('master_node_id')}, abort connection option {ml.get('abort_connection_option', 3)} "
                f"(written and read back by SDO)")
    else:
        text = "NOT configured: " + ("; ".join(ml.get("problems") or []) or "the drive has none")
    drill = ml.get("drill") or {}
    outcome = drill.get("outcome")
    if outcome == "reacted":
        emcy = ", ".join(drill.get("emcy") or []) or "none"
        text += (f"; drill: reacted {drill.get('reaction_ms')} ms after the master's last heartbeat "
                 f"(to {drill.get('state_after')}, EMCY {emcy})")
    elif outcome == "no reaction":
        text += (f"; drill: NO REACTION: still OPERATION ENABLED after {drill.get('waited_ms')} ms of the master's "
                 f"silence")
    elif outcome == "skipped":
        text += f"; drill skipped: {drill.get('note')}"
    else:
        text += "; not drilled"
    if ml.get("external_watchdog"):
        text += f"; external watchdog stated: {ml['external_watchdog']}"
    return text


def write_page(path: Path, title: str, parts: Iterable[str]) -> None:
    """Write a self-contained HTML page: the shell's style, then ``parts`` in order."""
    head = (f"<!doctype html><html><head><meta charset='utf-8'><title>{esc(title)}</title>"
            f"<style>{CSS}</style></head><body>")
    Path(path).write_text("\n".join([head, *parts, "</body></html>"]))
