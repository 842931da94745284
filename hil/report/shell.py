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
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hil.forks import can_fork, run_in_two
from hil.history.record import is_simulated
from hil.history.trends import fmt_serial

CSS = """body{font-family:sans-serif;max-width:1300px;margin:1em auto;color:#222;line-height:1.35}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}
th{background:#eee}td:first-child,th:first-child{text-align:left}img{max-width:100%}
.pass{color:#070}.fail{color:#b00}.inconclusive{color:#b36b00}.aborted,.incomplete{color:#666}.warn{color:#b60}
h1 .badge{color:#fff;padding:0 .35em;border-radius:3px}h1 .pass{background:#070}h1 .fail{background:#b00}
h1 .inconclusive{background:#d98a00}h1 .aborted,h1 .incomplete{background:#777}
h1 .simulated,.simulated{color:#fff;background:#5a3d99;padding:0 .35em;border-radius:3px}
p.simulated{padding:.3em .5em}
.signoff{border:2px solid #222;padding:.5em 1em;margin:1.5em 0;max-width:60em}
.signoff table{width:100%}.signoff td,.signoff th{text-align:left;border:none;padding:6px 8px}
.signoff th{background:none;width:14em}.signoff td.line{border-bottom:1px solid #222;height:2em}
details{margin:1em 0}summary{cursor:pointer;color:#555}pre{font-size:85%;background:#f6f6f6;padding:.5em}
small{color:#555}
@page{size:A4;margin:15mm 12mm}
@media print{body{max-width:none;margin:0;font-size:9pt;-webkit-print-color-adjust:exact;print-color-adjust:exact}
img{max-width:100%;height:auto;page-break-inside:avoid;break-inside:avoid}
table,.signoff,figure,tr{page-break-inside:avoid;break-inside:avoid}td,th{padding:2px 4px}
h1,h2,h3{page-break-after:avoid;break-after:avoid}details{display:block}summary{display:none}
.signoff{page-break-before:auto}}"""

#: the verdict words of a report's heading, each with its CSS class (colour)
STATUS_WORDS = {"pass": "PASS", "fail": "FAIL", "inconclusive": "INCONCLUSIVE", "aborted": "ABORTED",
                "incomplete": "INCOMPLETE"}


def pyplot():
    """matplotlib's pyplot on the Agg backend (no display), imported on first use."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def laid_out(fig: Any, dpi: int = 80) -> Any:
    """``fig`` laid out to be drawn at ``dpi``: the margins and the gaps between its axes fitted to their
    tick labels, axis labels, titles, legends and texts (matplotlib's tight layout, pad 1.08 font sizes);
    ``fig`` itself returned.

    The layout is computed at the dpi the figure is drawn at, so that the drawing (:func:`figure_uri`)
    reuses the layout's renderer and its text metrics, and nothing is laid out or cropped after it
    (neither ``Figure.tight_layout``, which leaves a placeholder layout engine that makes ``savefig``
    draw the whole figure once more first, nor ``bbox_inches="tight"``, two passes more): the picture
    is the figure's size, ``figsize`` times ``dpi``. Axes resized by the layout may pick other ticks,
    with wider labels than those it fitted (the calibration figure's left margin came out 8 px short):
    then it is computed again (up to 3 times), until the ticks it fitted are those drawn.
    """
    from matplotlib.layout_engine import TightLayoutEngine

    def ticks() -> list[tuple]:
        return [(tuple(axis.get_majorticklocs()), tuple(axis.get_minorticklocs()))
                for ax in fig.axes for axis in (ax.xaxis, ax.yaxis)]

    fig.set_dpi(dpi)
    engine = TightLayoutEngine()
    fitted = None
    for _ in range(3):
        now = ticks()
        if now == fitted:
            break
        engine.execute(fig)
        fitted = now
    return fig


def figure_uri(fig: Any, *, dpi: int = 80) -> str:
    """PNG data URI of a matplotlib figure, laid out (:func:`laid_out`) and drawn at ``dpi``; closes the
    figure."""
    buf = io.BytesIO()
    laid_out(fig, dpi).savefig(buf, format="png", dpi=dpi)
    pyplot().close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def img(fig: Any, *, dpi: int = 80) -> str:
    """An ``<img>`` element showing ``fig`` (see :func:`figure_uri`)."""
    return f"<img src='{figure_uri(fig, dpi=dpi)}'>"


@dataclass(frozen=True)
class Drawing:
    """A figure's ``<img>`` for :func:`drawn` (``draw``, a callable, e.g. around :func:`img`) with its
    number of ``axes``: what its drawing costs grows with them (the maintenance report's figures at 90
    dpi: 6 axes ~0.16 s of CPU, 4 ~0.15 s, 2 ~0.09 s, 1 ~0.06 s), and the two processes of
    :func:`drawn` take the figures with more axes first."""

    draw: Callable[[], str]
    axes: int = 1

    def __call__(self) -> str:
        return self.draw()


def drawn(parts: Sequence[str | Callable[[], str] | tuple], *, processes: int = 2) -> list[str]:
    """``parts`` with each callable (a figure's ``<img>``, :func:`img`; or a :class:`Drawing`) replaced by
    what it returns and each tuple of those joined into one string, the figures drawn by up to
    ``processes`` processes at once; the same strings in the same order as one process draws them.

    The second process is a fork of this one (nothing pickled in, the PNG data URIs pickled back), both
    taking the next figure not yet taken (:func:`hil.forks.run_in_two`): those with the most axes first
    (a :class:`Drawing`'s ``axes``, 1 for a bare callable), then in the order of ``parts``, so that the
    two end at about the same time (the costliest figure taken last would leave one process drawing it
    alone). A figure the fork did not return (it died, or is killed by the interrupt that stops this
    process) is drawn here. One process where there is no fork (:func:`hil.forks.can_fork`: no
    ``os.fork``, another thread runs; or ``os.fork`` fails), with fewer than two figures or
    ``processes`` below 2.
    """
    pieces = [list(p) if isinstance(p, tuple) else [p] for p in parts]
    flat = [x for p in pieces for x in p]
    jobs = {i: x for i, x in enumerate(flat) if callable(x)}
    done: dict[int, str] = {}
    if processes >= 2 and 2 <= len(jobs) and max(jobs) < 256 and can_fork():
        pyplot()  # imported once, before the fork: both processes have it
        done = run_in_two(jobs, order=sorted(jobs, key=lambda i: -getattr(jobs[i], "axes", 1)))
    out = [done[i] if i in done else (x() if callable(x) else x) for i, x in enumerate(flat)]
    it = iter(out)
    return ["".join(next(it) for _ in p) for p in pieces]


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


def heading(what: str, data: dict) -> str:
    """A report's ``<h1>``: what it is, the verdict in its colour (pass green, fail red, inconclusive
    amber, aborted and incomplete grey) and SIMULATED for simulated data (:func:`is_simulated`)."""
    status = str(data.get("status") or "")
    word = STATUS_WORDS.get(status, status.upper())
    sim = " <span class='simulated'>SIMULATED</span>" if is_simulated(data) else ""
    return f"<h1>{esc(what)}: <span class='badge {esc(status)}'>{esc(word)}</span>{sim}</h1>"


def page_title(what: str, data: dict) -> str:
    """The page's ``<title>`` (what a browser's tab and a printed page's header show): the verdict, and
    SIMULATED for simulated data."""
    status = str(data.get("status") or "")
    return (f"{what}: {STATUS_WORDS.get(status, status.upper())}"
            + (" (SIMULATED, not a real actuator)" if is_simulated(data) else ""))


_SIMULATED_WHAT = {"dry-run": "a dry-run: the check over CANopen against two simulated drives",
                   "simulate": "the check against the simulated plant (no CAN in between)",
                   "simulate-scenario": "a simulated normal-operation recording"}


def simulated_banner(data: dict) -> str:
    """For simulated data: a line under the heading saying so and what made it ("" for real data)."""
    if not is_simulated(data):
        return ""
    mode = (data.get("trace") or {}).get("mode")
    what = _SIMULATED_WHAT.get(mode, "simulated data (the simulator's truth is beside it)")
    return (f"<p class='simulated'><b>SIMULATED</b>: {esc(what)}. Not a real actuator: this report is no "
            "record of any aircraft's actuation.</p>")


def installation_rows(trace: dict) -> list[list[str]]:
    """Where and when in the aircraft's life (``--aircraft``, ``--position``, ``--rig``, ``--flight-hours``,
    ``--flight-cycles`` or the profile's ``[history]``), "—" where nobody said."""
    fh, fc = trace.get("flight_hours"), trace.get("flight_cycles")
    return [["aircraft", trace.get("aircraft") or "—"], ["position", trace.get("position") or "—"],
            ["rig", trace.get("rig") or "—"], ["flight hours", "—" if fh is None else f"{fh:g} FH"],
            ["flight cycles", "—" if fc is None else str(fc)]]


def serials(trace: dict) -> list[tuple[str, str]]:
    """Each EMA and its serial number as the plate and the history write it (``0x5E000101``)."""
    return [(f"EMA {k[-1]}", fmt_serial(ident.get("serial")))
            for k, ident in sorted((trace.get("identity") or {}).items()) if ident]


def recording_text(trace: dict) -> str:
    """The recording a result was analysed from, with its SHA-256 where the result carries it
    ("" inside a run folder of the check itself)."""
    rec = trace.get("recording")
    if not rec or trace.get("run_id"):
        return ""
    sha = (trace.get("files_sha256") or {}).get("recording")
    return (f"file <b>{esc(Path(rec).name)}</b> ({esc(rec)}" + (f", sha256 <code>{esc(sha)}</code>" if sha else "")
            + ")")


def identification(data: dict) -> str:
    """One paragraph under the heading naming what was checked: aircraft, position, flight hours,
    each EMA's serial, work order, and the file for a bare recording."""
    trace = data.get("trace") or {}
    fh = trace.get("flight_hours")
    items = [("aircraft", trace.get("aircraft")), ("position", trace.get("position")),
             ("flight hours", None if fh is None else f"{fh:g} FH"), ("work order", trace.get("work_order"))]
    text = [f"{k} <b>{esc(v)}</b>" for k, v in items if v is not None and v != ""]
    text += [f"{k} serial <b>{esc(v)}</b>" for k, v in serials(trace)]
    rec = recording_text(trace)
    if rec:
        text.append("analysed from the " + rec)
    line = "; ".join(text) or "no installation given"
    return f"<p class='ident'>{line[0].upper() + line[1:]}.</p>"


def signoff_block(data: dict, what: str = "maintenance check") -> str:
    """The block an inspector signs, at the end of the decision: the verdict signed for, who ran the
    check and for which work order (filled in where given), and lines for the inspector's name, the
    date and the signature (printable: never split over two pages)."""
    trace = data.get("trace") or {}
    status = str(data.get("status") or "")

    def given(v: object) -> str:
        return f"<td>{esc(v)}</td>" if v else "<td class='line'></td>"

    fh = trace.get("flight_hours")
    where = ", ".join(esc(v) for v in (trace.get("aircraft"), trace.get("position"),
                                       None if fh is None else f"{fh:g} FH") if v)
    sn = ", ".join(f"{k} {esc(v)}" for k, v in serials(trace))
    sim = ("<p class='simulated'><b>SIMULATED</b>: not a real actuator; not for release to service.</p>"
           if is_simulated(data) else "")
    return (f"<div class='signoff'><h3>Sign-off</h3>{sim}"
            f"<p>The {esc(what)} above, verdict <b class='{esc(status)}'>"
            f"{esc(STATUS_WORDS.get(status, status.upper()))}</b>"
            + (f", run {esc(trace['run_id'])}" if trace.get("run_id") else "")
            + (f"; {where}" if where else "") + (f"; {sn}" if sn else "") + ".</p><table>"
            f"<tr><th>check run by (operator)</th>{given(trace.get('operator'))}</tr>"
            f"<tr><th>work order</th>{given(trace.get('work_order'))}</tr>"
            "<tr><th>inspected by (name, licence)</th><td class='line'></td></tr>"
            "<tr><th>date</th><td class='line'></td></tr>"
            "<tr><th>signature</th><td class='line'></td></tr></table></div>")


def trace_lines(trace: dict | None) -> str:
    """The traceability block of a report: when, what software, which actuators, who, for what work order."""
    if not trace:
        return ""
    rows = [["started (UTC)", trace.get("started_utc") or "—"], ["analysed (UTC)", trace.get("analysed_utc") or "—"],
            ["software", f"{trace.get('software', {}).get('name', '')} {trace.get('software', {}).get('version', '')}"],
            ["operator", trace.get("operator") or "—"], ["work order", trace.get("work_order") or "—"],
            ["run id", trace.get("run_id") or "—"], ["mode", trace.get("mode") or "— (a recording without run record)"],
            *installation_rows(trace), ["recording", trace.get("recording") or "—"]]
    for k, ident in (trace.get("identity") or {}).items():
        if ident:
            h = {f: "not read" if ident.get(f) is None else f"0x{ident[f]:08X}"
                 for f in ("vendor_id", "product_code", "revision")}
            rows.append([f"{k} identity (0x1018)", f"vendor {h['vendor_id']}, product {h['product_code']}, revision "
                                                   f"{h['revision']}, serial {fmt_serial(ident.get('serial'))}"])
    for k, ml in (trace.get("master_loss") or {}).items():
        rows.append([f"{k} reaction to losing the master", master_loss_text(ml)])
    for k, lims in (trace.get("drive_limits") or {}).items():
        rows.append([f"{k} limits written to the drive and read back", drive_limits_text(lims, "drive")])
        rows.append([f"{k} limits not written (no writable object in its EDS)", drive_limits_text(lims, "master")])
    if trace.get("master_stalls") is not None:
        rows.append(["stalls of the master", master_stalls_text(trace["master_stalls"])])
    for k, fc in (trace.get("force_control") or {}).items():
        rows.append([f"{k} holds forces by", "its CST mode (target torque)" if fc == "cst" else
                     "the master's force loop on the measured force in CSP (its drive has no CST)"])
    for k, h in (trace.get("files_sha256") or {}).items():
        rows.append([f"{k} (sha256)", h[:16] + "…" if h else "—"])
    for i in trace.get("inputs") or ():  # every file this result was read from (hil.record.inputs)
        rows.append([f"read: {i['role']} (sha256)", f"{i['file']}: " + (i["sha256"] or "—")[:16]])
    return "<h2>Traceability</h2>" + identity_warning(trace.get("identity")) + table(["item", "value"], rows)


def identity_warning(identity: dict | None) -> str:
    """A line saying so where EMA 1 and EMA 2 report one serial number (hil.record.runrecord.shared_serial);
    empty otherwise."""
    from hil.record.runrecord import shared_serial

    clash = shared_serial(identity)
    return "" if clash is None else f"<p class='fail'><b>Identity:</b> {esc(clash)}.</p>"


def master_stalls_text(st: dict) -> str:
    """One line of the master's stalls (meta.json ``stalls``): how many, the longest, the first, the limit."""
    limit = f"limit {st['limit_ms']:g} ms, {st['limit']}"
    injected = st.get("injected")
    how = (f"; injected: {injected['stall_ms']:g} ms every {injected['every_s']:g} s on average (dry-run)"
           if injected else "")
    if not st["count"]:
        return f"none ({limit}){how}"
    first = f", the first at {st['at'][0][0]:.3f} s" if st["at"] else ""
    return f"{st['count']}, the longest {st['longest_ms']:g} ms{first} ({limit}){how}"


def drive_limits_text(lims: list[dict], kept_by: str) -> str:
    """The limits of one drive kept by ``kept_by`` ("drive": written and read back; "master": the drive's EDS
    has no such object), each with its object and value in the drive's unit and the profile's."""
    got = [f"{x['limit']} {x['object']} = {x['value']} {x['unit']} ({x['si_value']:g} {x['si_unit']})"
           for x in lims if x.get("kept_by") == kept_by]
    return "; ".join(got) or "none"


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
        emcy = ", ".join(drill.get("emcy") or []) or "none"
        text += (f"; drill: NO REACTION: still OPERATION ENABLED after {drill.get('waited_ms')} ms of the master's "
                 f"silence (EMCY {emcy})")
    elif outcome == "skipped":
        text += f"; drill skipped: {drill.get('note')}"
    elif outcome == "not run":
        why = drill.get("note") or "the preflight stopped before it"
        text += f"; drill not run ({why})"
    else:
        text += "; not drilled"
    if ml.get("external_watchdog"):
        text += f"; external watchdog stated: {ml['external_watchdog']}"
    return text


def write_page(path: Path, title: str, parts: Iterable[str]) -> None:
    """Write a self-contained HTML page: the shell's style, then ``parts`` in order."""
    Path(path).write_text(page_html(title, parts))


def page_html(title: str, parts: Iterable[str]) -> str:
    """The text of a self-contained HTML page (:func:`write_page`)."""
    head = (f"<!doctype html><html><head><meta charset='utf-8'><title>{esc(title)}</title>"
            f"<style>{CSS}</style></head><body>")
    return "\n".join([head, *parts, "</body></html>"])
