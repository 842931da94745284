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
.signoff{border:2px solid #222;padding:.5em 1em;margin:1.5em 0;max-width:60em;overflow-wrap:anywhere}
.signoff table{width:100%;table-layout:fixed}.signoff td,.signoff th{text-align:left;border:none;padding:6px 8px}
.signoff th{background:none;width:14em}.signoff td.line{border-bottom:1px solid #222;height:2em}
.signoff .unknown{border:2px solid #b60;padding:.3em .5em;color:#222}
.ident,.run{overflow-wrap:anywhere}table.items td,table.items th{text-align:left}table.items td:first-child{width:15em}
details{margin:1em 0}summary{cursor:pointer;color:#555}pre{font-size:85%;background:#f6f6f6;padding:.5em}
small{color:#555}
table.sheet,.sheet>tbody,.sheet>tbody>tr,.sheet>tbody>tr>td{display:block;border:none;margin:0;padding:0;text-align:left}
.sheet>thead,.sheet>tfoot{display:none}
@page{size:A4;margin:15mm 12mm;
@bottom-right{content:"page " counter(page) " of " counter(pages);font:8pt sans-serif;color:#555}}
@media print{body{max-width:none;margin:0;font-size:9pt;-webkit-print-color-adjust:exact;print-color-adjust:exact}
img{max-width:100%;height:auto;page-break-inside:avoid;break-inside:avoid}
table,.signoff,figure,tr,section.keep{page-break-inside:avoid;break-inside:avoid}td,th{padding:2px 4px}
table.long{page-break-inside:auto;break-inside:auto}thead{display:table-header-group}
h1,h2,h3{page-break-after:avoid;break-after:avoid}details{display:block}summary{display:none}
.signoff{page-break-before:auto}
table.sheet{display:table;width:100%;margin:0;border:none;page-break-inside:auto;break-inside:auto}.sheet>tbody{display:table-row-group}
.sheet>thead{display:table-header-group}.sheet>tfoot{display:table-footer-group}
.sheet>tbody>tr,.sheet>thead>tr,.sheet>tfoot>tr{display:table-row;page-break-inside:auto;break-inside:auto}
.sheet>tbody>tr>td,.sheet>thead>tr>td,.sheet>tfoot>tr>td{display:table-cell;border:none;padding:0;text-align:left}
.sheet>thead>tr>td{font-size:8pt;color:#555;border-bottom:1px solid #999;padding-bottom:1mm}
.sheet>tfoot>tr>td{font-size:8pt;color:#555;border-top:1px solid #999;padding-top:1mm}}"""

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


#: Rows from which a table may split between pages when printed (``class='long'``), its header repeated on each:
#: printed at 9 pt a row of one line is 5.4 mm high (measured in Chromium 156: a 4.3 mm line, its padding and
#: border), and an A4 page leaves 253 mm for the content (297 mm less the 15 mm margins and the running header
#: and footer, about 7 mm each): a heading (about 10 mm), the table's header row and 40 rows (221 mm) fit on a
#: fresh page with some 20 mm to spare for a few cells wrapped on two lines. A shorter table moves whole to the
#: next page rather than split (``break-inside: avoid``); a longer one may not fit any page, and a table taller
#: than a page is split by every browser whatever it asks (docs/report.md, *Printing*).
LONG_TABLE_ROWS = 40


def table(columns: Sequence[str], rows: Iterable[Sequence[object]], *, raw: bool = False, css: str = "") -> str:
    """An HTML table; ``columns`` as from :func:`column`, cells escaped unless ``raw``. Its header is a
    ``<thead>`` (repeated on each printed page a table spans); printed, a table of fewer than
    :data:`LONG_TABLE_ROWS` rows is never split over two pages, a longer one only between rows. ``css``: its
    class (``items``: a list of items and their words, left-aligned)."""
    cell = (lambda c: str(c)) if raw else esc
    head = "".join(f"<th>{esc(c)}</th>" for c in columns)
    body = ["<tr>" + "".join(f"<td>{cell(c)}</td>" for c in r) + "</tr>" for r in rows]
    classes = " ".join(c for c in (css, "long" if len(body) >= LONG_TABLE_ROWS else "") if c)
    kind = f" class='{classes}'" if classes else ""
    return f"<table{kind}><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


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
    """The page's ``<title>`` (what a browser's tab and the header it prints on every page show): the verdict,
    SIMULATED for simulated data, and the run id."""
    status = str(data.get("status") or "")
    run_id = (data.get("trace") or {}).get("run_id")
    return (f"{what}: {STATUS_WORDS.get(status, status.upper())}"
            + (" (SIMULATED, not a real actuator)" if is_simulated(data) else "")
            + (f" · run {run_id}" if run_id else ""))


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
    each EMA's serial, work order, and the file for a bare recording; then when, by which software and which
    run (:func:`run_facts`)."""
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
    return f"<p class='ident'>{line[0].upper() + line[1:]}.</p>" + run_facts(data)


def unknown_identity(trace: dict) -> list[str]:
    """What a result does not identify: "the serial number of EMA 1" (its drive's 0x1018 serial not read, or
    0: none set; a bare recording has none), "... of EMA 2", "the aircraft" (no ``--aircraft`` nor the
    profile's ``history.aircraft``); empty when all are known."""
    ident = trace.get("identity") or {}
    out = [f"the serial number of EMA {k}" for k in (1, 2) if not (ident.get(f"ema{k}") or {}).get("serial")]
    return out + ([] if trace.get("aircraft") else ["the aircraft"])


def _unknown_words(missing: list[str], trace: dict) -> str:
    """The sign-off's box for a result that does not say which actuators it is of (""; all are known)."""
    serials = [m for m in missing if m.startswith("the serial")]
    if not serials:
        return ""
    bare = not trace.get("run_id")
    why = (" It was analysed from a recording file alone (a CSV or CAN log without its run folder): nothing "
           "read the actuators' identity from their drives." if bare else
           " The drives did not report it when the check read their identity (object 0x1018).")
    return ("<div class='unknown'><p><b>Actuators not identified.</b> This result does not say which actuators it "
            f"is of: it records no {', '.join(m.removeprefix('the ') for m in missing)}.{why} Nothing in this "
            "report ties the verdict to a particular actuator. Before signing, read each actuator's serial number "
            "off its identification plate (and the aircraft and position off the work order) and write them in the "
            "lines below; do not sign for an actuator that has not been identified.</p></div>")


def signoff_block(data: dict, what: str = "maintenance check") -> str:
    """The block an inspector signs, at the end of the decision: the verdict signed for, who ran the
    check and for which work order (filled in where given), and lines for the inspector's name, the
    date and the signature (printable: never split over two pages). A result that does not identify its
    actuators (:func:`unknown_identity`: a bare recording, a serial not read) says so in the block, in words,
    with a line to fill in for each serial (and the aircraft) it lacks. Long words wrap inside the block."""
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
    missing = unknown_identity(trace)
    fill = "".join(f"<tr><th>EMA {m[-1]} serial number (from its plate)</th><td class='line'></td></tr>"
                   for m in missing if m.startswith("the serial"))
    if "the aircraft" in missing:
        fill += "<tr><th>aircraft and position</th><td class='line'></td></tr>"
    return (f"<div class='signoff'><h3>Sign-off</h3>{sim}{_unknown_words(missing, trace)}"
            f"<p>The {esc(what)} above, verdict <b class='{esc(status)}'>"
            f"{esc(STATUS_WORDS.get(status, status.upper()))}</b>"
            + (f", run {esc(trace['run_id'])}" if trace.get("run_id") else "")
            + (f"; {where}" if where else "") + (f"; {sn}" if sn else "") + ".</p><table>" + fill +
            f"<tr><th>check run by (operator)</th>{given(trace.get('operator'))}</tr>"
            f"<tr><th>work order</th>{given(trace.get('work_order'))}</tr>"
            "<tr><th>inspected by (name, licence)</th><td class='line'></td></tr>"
            "<tr><th>date</th><td class='line'></td></tr>"
            "<tr><th>signature</th><td class='line'></td></tr></table></div>")


def run_facts(data: dict) -> str:
    """Page 1's line of when and by what: the check's date and time (UTC), the software and its version (the
    check's and the analysis', where they differ), and the run id; for a recording without run record, said."""
    trace = data.get("trace") or {}
    sw = trace.get("software") or {}
    version = f"{sw.get('name') or 'emacheck'} {sw.get('version') or '?'}"
    ran = sw.get("check_run_with")
    if ran and ran != sw.get("version"):
        version = f"{sw.get('name') or 'emacheck'} {ran} (the check), {sw.get('version')} (this analysis)"
    started = trace.get("started_utc")
    when = (f"check started <b>{esc(_utc(started))}</b>" if started else
            "check date and time not recorded (a recording without its run folder)")
    analysed = trace.get("analysed_utc")
    run = (f"run <b><code>{esc(trace['run_id'])}</code></b>" if trace.get("run_id") else
           "no run id (a recording without its run folder)")
    return (f"<p class='run'>{when[0].upper() + when[1:]}"
            + (f", analysed {esc(_utc(analysed))}" if analysed else "")
            + f"; software <b>{esc(version)}</b>; {run}.</p>")


def _utc(iso: str) -> str:
    """``2026-11-26T13:55:58+00:00`` as ``2026-11-26 13:55:58 UTC`` (other text as it is)."""
    return iso.replace("T", " ").replace("+00:00", " UTC") if iso.endswith("+00:00") else iso


def running_head(what: str, data: dict) -> str:
    """The line printed at the top of every page of a report: what it is, its verdict, its run id (or the
    recording's file and SHA-256 for a recording without run folder), the software."""
    trace = data.get("trace") or {}
    status = str(data.get("status") or "")
    sw = trace.get("software") or {}
    if trace.get("run_id"):
        run = f"run {trace['run_id']}"
    else:
        rec, sha = trace.get("recording"), (trace.get("files_sha256") or {}).get("recording")
        run = ("no run id; file " + Path(rec).name + (f", sha256 {sha[:16]}…" if sha else "")) if rec else "no run id"
    sim = " SIMULATED" if is_simulated(data) else ""
    return (f"{what}: {STATUS_WORDS.get(status, status.upper())}{sim} · {run} · "
            f"{sw.get('name') or 'emacheck'} {sw.get('version') or ''}").strip()


def _state_words(state: str | None) -> str:
    """A CiA 402 state as its name reads (``SWITCH_ON_DISABLED``: Switch on disabled); "not known" for None."""
    return "not known" if not state else state.replace("_", " ").capitalize()


def _drive_left_row(k: str, d: dict) -> list[str]:
    state = _state_words(d.get("state")) if d.get("node") is not None else "— (no CANopen drive: simulated plant)"
    safe = ("—" if d.get("safe") is None else "yes" if d["safe"] else
            "<b class='fail'>NOT confirmed safe</b>" + ("" if d.get("reachable", True) else " (unreachable)"))
    emcy = d.get("emcy") or []
    codes = "; ".join(esc(f"EMCY 0x{e['code']:04X} ({e['text']}) at t = {e['t_s']:.3f} s") for e in emcy) or "none"
    count = d.get("emcy_count") or 0
    if count > len(emcy):
        codes += f" (the last {len(emcy)} of {count})"
    num = (lambda key, nd: "—" if d.get(key) is None else f"{d[key]:.{nd}f}")  # noqa: E731
    return [f"EMA {k[-1]}" + ("" if d.get("node") is None else f" (node {d['node']})"),
            esc(state) + (f"<br><small>{esc(d['seen'])}</small>" if d.get("seen") else ""), safe,
            num("t_s", 3), num("position_mm", 3), num("stroke_mm", 3), num("force_N", 0), codes]


def drives_left(data: dict) -> str:
    """Where each drive was left when the check stopped (result.json ``trace.drives_last``): its CiA 402 state
    after the stop and whether it was confirmed safe, its last complete sample (time, ram position from the
    motor angle, LVDT stroke, force) and the EMCYs it sent; for a run cut off before its stop, said."""
    left = (data.get("trace") or {}).get("drives_last")
    head = "<h3>Where the drives were left</h3>"
    if not left:
        return head + ("<p>Not recorded: the check was cut off before its stop was recorded (the master was killed "
                       "or lost power). The last row of signals.csv is the last sample that reached the disk.</p>")
    rows = [_drive_left_row(k, d) for k, d in sorted(left.items())]
    cols = [column("EMA"), column("CiA 402 state after the stop"), column("safe"), column("last sample t", "s"),
            column("position φ/i_total", "mm"), column("stroke (LVDT)", "mm"), column("force", "N"),
            column("EMCY (fault codes)")]
    return "<section class='keep'>" + head + table(cols, rows, raw=True) + "</section>"


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
    return ("<section class='keep'><h2>Traceability</h2>" + identity_warning(trace.get("identity"))
            + table(["item", "value"], rows, css="items") + "</section>")


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


def write_page(path: Path, title: str, parts: Iterable[str], running: str | None = None) -> None:
    """Write a self-contained HTML page: the shell's style, then ``parts`` in order (:func:`page_html`)."""
    Path(path).write_text(page_html(title, parts, running))


def page_html(title: str, parts: Iterable[str], running: str | None = None) -> str:
    """The text of a self-contained HTML page (:func:`write_page`): ``parts`` inside a sheet whose header and
    footer (``running``, e.g. :func:`running_head`; else ``title``) the browser repeats on every printed page
    (a table's ``<thead>``/``<tfoot>``; hidden on screen), page numbers in the ``@page`` margin box (docs/report.md,
    *Printing*, says which browser prints what)."""
    line = esc(running or title)
    head = (f"<!doctype html><html><head><meta charset='utf-8'><title>{esc(title)}</title>"
            f"<style>{CSS}</style></head><body><table class='sheet'><thead><tr><td>{line}</td></tr></thead>"
            f"<tfoot><tr><td>{line}</td></tr></tfoot><tbody><tr><td>")
    return "\n".join([head, *parts, "</td></tr></tbody></table></body></html>"])
