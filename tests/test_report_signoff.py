"""The report an inspector signs (issue 34, part 7): heading, what was checked, the decision with a
sign-off block, one meaning of ±, serials in hex, SIMULATED, the bare file named, print on A4, and legends
that do not cover the data.

Fast: the report's text is built from a synthetic result (as result.json carries it) and the figures from
a synthetic force fight; one slow test reads a whole report of a simulated check made inconclusive by a
tighter B_spec."""

from __future__ import annotations

import hashlib
import html
import re

import numpy as np
import pytest

from blf.maint import blf_maint
from blf.maint.verdict import decide, maint_uncertainty, overall
from hil.analysis.maint import verdict_entry
from hil.report import shell
from hil.report.maint import figure_dfdd, figure_lines, head_parts, reading_text, uncertainty_section
from support.blfmaint_data import FS_HZ, make_force_fight

CHANNELS = ("int1", "int2", "ext")
SIGMA = {"int1": 0.00018, "int2": 0.00021, "ext": 0.00027}  # the regression's statistical sigma [mm]
SERIALS = {"ema1": 0x5E000101, "ema2": 0x5E000102}
RULE = ("ISO 14253-1 guard band: pass if B + U <= limit on every channel, fail if B - U > limit on any, "
        "otherwise inconclusive; U expanded uncertainty, k = 2")
TRUTH = {"backlash_mm": {"int1": 0.1, "int2": 0.12, "ext": 0.1},
         "stiffness_N_per_mm": {ch: {"left": 80000.0, "right": 80000.0} for ch in ("int1", "int2", "ext")},
         "calibration": {"ema1": {"pitch": 1.075}, "ema2": {"pitch": 0.98}}}
NOT_MEASURED = "the force fight never reached contact on the tension side"


def make_result(*, backlash=None, limits=None, mode="run", operator="A. Inspector", work_order="WO-4711",
                run_id="f89b331810fb45fe8eae7d854c1eeafe", recording="/runs/ail-left/signals.csv",
                files=None, truth=None) -> dict:
    """A result.json as analyze_and_report writes it, with verdicts and U from blf.maint.verdict."""
    backlash = backlash or {"int1": 0.1002, "int2": 0.1196, "ext": 0.1002}
    limits = limits or {"int1": 0.2, "int2": 0.2, "ext": 0.2}
    verdict, decided = {}, {}
    for ch in CHANNELS:
        b = backlash[ch]
        if b is None:
            v, u = decide(None, None, limits[ch], missing=NOT_MEASURED), None
        else:
            u = maint_uncertainty(b, SIGMA[ch], 1e-5)
            v = decide(b, u.expanded_mm, limits[ch])
        decided[ch] = v
        verdict[ch] = verdict_entry(v, u)
    result = {
        "status": overall(decided), "verdict": verdict, "decision_rule": RULE,
        "backlash_mm": dict(backlash),
        "backlash_sigma_mm": {ch: None if backlash[ch] is None else SIGMA[ch] for ch in CHANNELS},
        "stiffness_N_per_mm": {ch: {"left": 80000.0, "right": 80100.0} for ch in CHANNELS},
        "calibration": {k: {"pitch": 1.075, "offset_mm": 0.2, "nonlinearity_mm": 0.005, "rmse_mm": 0.004}
                        for k in ("ema1", "ema2")},
        "spec": {"backlash_int_mm": limits["int1"], "backlash_ext_mm": limits["ext"]},
        "notes": [],
        "trace": {"run_id": run_id, "started_utc": "2026-11-26T13:55:58+00:00",
                  "analysed_utc": "2026-11-26T13:56:09+00:00",
                  "software": {"name": "emacheck", "version": "0.1.0", "check_run_with": "0.1.0"},
                  "operator": operator, "work_order": work_order,
                  "identity": {k: {"node": int(k[-1]), "vendor_id": 3642, "product_code": 1026, "revision": 65536,
                                   "serial": s} for k, s in SERIALS.items()},
                  "files_sha256": files if files is not None else {"actuation": "c6" * 32},
                  "recording": recording, "mode": mode, "aircraft": "D-EMAX", "position": "left aileron",
                  "rig": None, "flight_hours": 1234.0, "flight_cycles": None},
    }
    if truth is not None:
        result["truth"] = truth
    return result


def page(result: dict) -> str:
    """The report's text as write_report lays it out before the figures (heading, decision, sign-off,
    calibration, traceability, uncertainty)."""
    return "\n".join([*head_parts(result, "<p>intro</p>"), shell.trace_lines(result["trace"]),
                      uncertainty_section(result)])


def text_of(markup: str) -> str:
    """What a reader sees: tags dropped, entities decoded."""
    return html.unescape(re.sub(r"<[^>]+>", "", markup))


def section(markup: str, start: str) -> str:
    """From the heading ``start`` to the next <h2>."""
    i = markup.index(start)
    j = markup.find("<h2>", i + len(start))
    return markup[i:] if j < 0 else markup[i:j]


# ---------------------------------------------------------------------------- sign-off


def test_the_decision_ends_in_a_sign_off_block_with_operator_and_work_order_filled_in():
    doc = page(make_result())
    decision = section(doc, "<h2>Decision</h2>")
    assert "<div class='signoff'><h3>Sign-off</h3>" in decision  # inside the decision section
    block = decision[decision.index("<div class='signoff'>"):]
    assert "<th>check run by (operator)</th><td>A. Inspector</td>" in block
    assert "<th>work order</th><td>WO-4711</td>" in block
    for blank in ("inspected by (name, licence)", "date", "signature"):
        assert f"<th>{blank}</th><td class='line'></td>" in block
    # what is signed for: the verdict, the run, the installation and the actuators
    signed = text_of(block)
    assert "verdict PASS" in signed and "f89b331810fb45fe8eae7d854c1eeafe" in signed
    assert "D-EMAX, left aileron, 1234 FH" in signed and "EMA 1 0x5E000101, EMA 2 0x5E000102" in signed


def test_sign_off_without_operator_or_work_order_leaves_lines_to_fill():
    block = shell.signoff_block(make_result(operator=None, work_order=None))
    assert block.count("<td class='line'></td>") == 5
    assert "A. Inspector" not in block and "WO-4711" not in block


# ---------------------------------------------------------------------------- one meaning of ±


def plus_minus_values(text: str) -> list[str]:
    """Every number printed after a ± (or its ASCII spelling +-), as printed."""
    return re.findall(r"(?:±|\+-)\s*=?\s*(\d+\.\d+)", text)


def test_every_plus_minus_in_the_report_is_U_at_its_printed_resolution():
    result = make_result(limits={"int1": 0.2, "int2": 0.123, "ext": 0.2})  # int2 straddles: "B +- U = ..."
    text = text_of(page(result))
    values = plus_minus_values(text)
    assert values, "the inconclusive reason prints B +- U"
    us = [result["verdict"][ch]["uncertainty_mm"] for ch in CHANNELS]
    for v in values:
        nd = len(v.split(".")[1])
        assert any(v == f"{u:.{nd}f}" for u in us), f"± {v} is no channel's U {us}"
    sigmas = {f"{s:.4f}" for s in SIGMA.values()} | {f"{s:.5f}" for s in SIGMA.values()}
    assert not sigmas & set(values)
    # the statistical sigma is labelled as such where it is shown
    assert "σ (statistical) [mm]" in text


@pytest.fixture(scope="module")
def fights():
    """BLFmaint on a synthetic internal (F falls with D) and external (F rises with D) force fight."""
    out = {}
    for ch, kw in (("int2", dict(backlash_mm=0.12, slope_sign=-1)),
                   ("ext", dict(backlash_mm=0.10, slope_sign=1, stiffness_left_N_per_mm=18_000.0,
                                stiffness_right_N_per_mm=18_000.0, f_max_N=12_000.0))):
        d, f, _, _ = make_force_fight(np.random.default_rng(11), **kw)
        out[ch] = d, f, blf_maint(d, f, FS_HZ)
    return out


def test_the_figure_prints_B_plus_minus_U_and_the_sigma_labelled(fights):
    from matplotlib.text import Text

    d, f, r = fights["ext"]
    u = maint_uncertainty(r.backlash_mm, r.backlash_sigma_mm, 1e-5).expanded_mm
    assert f"{u:.4f}" != f"{r.backlash_sigma_mm:.4f}"
    fig = figure_lines("ext", d, f, r, None, u)
    texts = [t.get_text() for t in fig.findobj(Text) if t.get_text()]
    shell.pyplot().close(fig)
    joined = "\n".join(texts)
    assert plus_minus_values(joined) == [f"{u:.4f}"]
    assert f"σ (statistical) = {r.backlash_sigma_mm:.4f} mm" in joined
    assert f"B = {r.backlash_mm:.4f} mm ± {u:.4f} mm (U, k = 2)" in reading_text("ext", r, u, None)
    # without U (nothing decided) no ± at all, the sigma still labelled
    assert "±" not in reading_text("ext", r, None, None)


# ---------------------------------------------------------------------------- legends off the data


def _assert_legends_clear_of_data(fig) -> int:
    shell.laid_out(fig, 90)  # as the report lays it out and draws it
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    checked = 0
    for ax in fig.axes:
        boxes = [a.get_window_extent(renderer) for a in [ax.get_legend()] if a is not None]
        boxes += [t.get_window_extent(renderer) for t in ax.texts if t.get_text()]  # the reading beside it
        for box in boxes:
            for line in ax.lines:
                xy = np.asarray(line.get_xydata(), dtype=float)
                if xy.size == 0 or line.get_transform() != ax.transData:
                    continue  # axhline/axvline span the axes in axes coordinates: not data points
                pts = ax.transData.transform(xy[np.all(np.isfinite(xy), axis=1)])
                inside = ((pts[:, 0] >= box.x0) & (pts[:, 0] <= box.x1)
                          & (pts[:, 1] >= box.y0) & (pts[:, 1] <= box.y1))
                assert not inside.any(), (f"{ax.get_title()}: {int(inside.sum())} point(s) of "
                                          f"{line.get_label()!r} under a legend or text box")
                checked += len(pts)
    return checked


@pytest.mark.parametrize("ch, which", [("int2", "dfdd"), ("ext", "lines"), ("int2", "lines"), ("ext", "dfdd")])
def test_no_legend_or_reading_covers_the_data(fights, ch, which):
    d, f, r = fights[ch]
    fig = figure_dfdd(ch, d, f, r) if which == "dfdd" else figure_lines(ch, d, f, r, None, 0.0058)
    try:
        assert all(ax.get_legend() is not None for ax in fig.axes)
        assert _assert_legends_clear_of_data(fig) > 1000
    finally:
        shell.pyplot().close(fig)


@pytest.mark.parametrize("ch, which", [("int2", "dfdd"), ("ext", "lines")])
def test_laid_out_figure_fits_its_picture(fights, ch, which):
    """The report's layout (shell.laid_out, no crop after it): everything drawn lies inside the picture,
    with the layout's margin, and the layout is a fixed point (laying it out again moves its margins by
    less than 0.003 of the figure, 2.4 px)."""
    d, f, r = fights[ch]
    fig = figure_dfdd(ch, d, f, r) if which == "dfdd" else figure_lines(ch, d, f, r, None, 0.0058)
    try:
        shell.laid_out(fig, 90)
        params = dict(vars(fig.subplotpars))
        fig.canvas.draw()
        box = fig.get_tightbbox(fig.canvas.get_renderer())  # inches
        w, h = fig.get_size_inches()
        pad = 5 / 90  # inches: 5 px at 90 dpi (the layout's pad is 1.08 font sizes, ~13 px)
        assert box.x0 >= pad and box.y0 >= pad and box.x1 <= w - pad and box.y1 <= h - pad, (box, w, h)
        shell.laid_out(fig, 90)
        # (the legend beside the axes is placed at 1.01 axes widths: a pass moves it ~1 px, 0.0013)
        assert dict(vars(fig.subplotpars)) == pytest.approx(params, abs=0.003)
    finally:
        shell.pyplot().close(fig)


# ---------------------------------------------------------------------------- what was checked


def test_serials_in_hex_as_on_the_plate_and_in_the_history():
    from hil.history import trends

    assert shell.fmt_serial is trends.fmt_serial  # one formatting function, not a copy
    doc = page(make_result())
    assert doc.count("0x5E000101") >= 3 and doc.count("0x5E000102") >= 3  # identification, sign-off, trace
    assert str(0x5E000101) not in doc and str(0x5E000102) not in doc


def test_aircraft_position_flight_hours_and_work_order_shown():
    doc = page(make_result())
    ident = doc[doc.index("<p class='ident'>"):doc.index("<h2>Decision</h2>")]
    for item in ("D-EMAX", "left aileron", "1234 FH", "WO-4711"):
        assert item in ident
    trace = text_of(section(doc, "<h2>Traceability</h2>"))
    assert "aircraftD-EMAX" in trace and "positionleft aileron" in trace and "flight hours1234 FH" in trace


@pytest.mark.parametrize("mode, truth, simulated", [
    ("dry-run", None, True), ("simulate", None, True), ("run", None, False), (None, None, False),
    (None, TRUTH, True),  # the simulator's truth beside a result: simulated data
])
def test_simulated_in_heading_and_title_of_simulated_data_only(mode, truth, simulated):
    result = make_result(mode=mode, truth=truth)
    h1, title = shell.heading("emacheck maintenance check", result), shell.page_title("emacheck report", result)
    doc = page(result)
    if simulated:
        assert "SIMULATED" in h1 and "SIMULATED" in title and "not a real actuator" in title
        assert "<p class='simulated'><b>SIMULATED</b>" in doc and "not for release to service" in doc
    else:
        assert "SIMULATED" not in doc and "SIMULATED" not in title
    if mode == "dry-run":
        assert "a dry-run: the check over CANopen against two simulated drives" in doc


# ---------------------------------------------------------------------------- inconclusive


def test_inconclusive_heading_in_its_colour_and_each_reason_once():
    result = make_result(backlash={"int1": 0.1002, "int2": 0.1196, "ext": None},
                         limits={"int1": 0.2, "int2": 0.123, "ext": 0.2})
    assert result["status"] == "inconclusive"
    doc = page(result)
    assert "<h1>emacheck maintenance check: <span class='badge inconclusive'>INCONCLUSIVE</span>" in doc
    css = shell.CSS
    amber = re.search(r"\.inconclusive\{color:(#[0-9a-f]+)\}", css).group(1)
    colours = {c: re.search(rf"(?<![ .])\.{c}\{{color:(#[0-9a-f]+)", css).group(1) for c in ("pass", "fail")}
    assert amber not in colours.values() and "h1 .inconclusive{background:" in css
    assert re.search(r"\.aborted,\.incomplete\{color:", css)
    for ch in CHANNELS:
        reason = result["verdict"][ch]["reason"]
        assert doc.count(html.escape(reason)) == 1, reason
    assert doc.count(NOT_MEASURED) == 1


def test_analysis_adds_no_note_repeating_a_channels_reason():
    """The duplicate came from hil.analysis.maint: a channel BLFmaint could not measure got a note
    "ch: why" beside its verdict's reason "not measured: why"."""
    import inspect

    from hil.analysis import maint

    src = inspect.getsource(maint.analyze_signals)
    assert 'notes.append(f"{ch}: {exc}")' not in src


# ---------------------------------------------------------------------------- a bare recording


def test_a_bare_recording_is_named_with_its_sha256():
    sha = "a3" * 32
    result = make_result(run_id=None, mode=None, recording="/data/flight-042.csv", files={"recording": sha})
    ident = page(result)[:page(result).index("<h2>Decision</h2>")]
    assert "analysed from the file <b>flight-042.csv</b>" in ident and sha in ident
    # a check's own run folder: the recording is its signals.csv, not named up front
    assert "analysed from" not in page(make_result())


def test_trace_of_a_bare_recording_carries_its_sha256(tmp_path):
    from hil.cli.result import trace_of

    rec = tmp_path / "flight-042.csv"
    rec.write_text("t,phi1,phi2,s1,s2,F1,F2\n0,0,0,0,0,0,0\n")
    t = trace_of(None, rec)
    assert t["files_sha256"] == {"recording": hashlib.sha256(rec.read_bytes()).hexdigest()}
    assert t["recording"] == str(rec) and t["run_id"] is None


# ---------------------------------------------------------------------------- print


def test_print_stylesheet_a4_and_nothing_split(tmp_path):
    css = shell.CSS
    assert re.search(r"@page\{size:A4;margin:\d+mm", css)
    printed = css[css.index("@media print"):]
    assert "img{max-width:100%" in printed
    assert re.search(r"table,\.signoff[^{]*\{page-break-inside:avoid;break-inside:avoid", printed)
    assert re.search(r"img\{[^}]*page-break-inside:avoid", printed)
    out = tmp_path / "r.html"
    result = make_result(mode="dry-run")
    shell.write_page(out, shell.page_title("emacheck maintenance check", result), head_parts(result, ""))
    doc = out.read_text()
    assert "@page{size:A4" in doc
    assert ("<title>emacheck maintenance check: PASS (SIMULATED, not a real actuator) · run "
            "f89b331810fb45fe8eae7d854c1eeafe</title>") in doc


# ---------------------------------------------------------------------------- a whole report


@pytest.mark.slow
def test_a_whole_inconclusive_report_of_a_simulated_check(default_run, tmp_path):
    """analyze of a simulated check against a B_spec that int2's reading straddles: the heading, each
    reason once, every ± a U of result.json, SIMULATED."""
    import json

    from hil.cli import main
    from support.profiles import write_profile_variant

    run_dir, _ = default_run
    act = write_profile_variant("actuation.toml", tmp_path / "actuation.toml",
                                {"mechanics": {"backlash_spec_int_mm": 0.123, "backlash_spec_ext_mm": 0.2}})
    out = tmp_path / "analysis"
    assert main(["analyze", str(run_dir), "--profile", str(act), "--out", str(out), "--no-history",
                 "--aircraft", "D-EMAX", "--flight-hours", "1234"]) == 5
    result = json.loads((out / "result.json").read_text())
    doc = (out / "report.html").read_text()
    assert "<span class='badge inconclusive'>INCONCLUSIVE</span> <span class='simulated'>SIMULATED</span>" in doc
    text = text_of(doc)
    us = [v["uncertainty_mm"] for v in result["verdict"].values()]
    for v in plus_minus_values(text):
        assert any(v == f"{u:.{len(v.split('.')[1])}f}" for u in us), v
    for v in result["verdict"].values():
        assert doc.count(html.escape(v["reason"])) == 1
    assert "D-EMAX" in doc and "1234 FH" in doc and "<div class='signoff'>" in doc


@pytest.mark.slow
def test_the_serv_report_of_a_simulated_recording(tmp_path):
    """serv_report.html: SIMULATED in heading and title, the serials in hex, the sign-off after the
    decision, the statistical sigma labelled, every ± a U of serv.json."""
    import json

    from hil.cli import main

    rec = tmp_path / "rec"
    assert main(["simulate", "--scenario", "full-stroke", "--out", str(rec)]) == 0
    out = tmp_path / "serv"
    assert main(["serv", str(rec), "--out", str(out), "--operator", "A. Inspector", "--work-order", "WO-4711"]) == 0
    data = json.loads((out / "serv.json").read_text())
    doc = (out / "serv_report.html").read_text()
    assert "<span class='badge pass'>PASS</span> <span class='simulated'>SIMULATED</span></h1>" in doc
    assert (f"<title>emacheck serv: PASS (SIMULATED, not a real actuator) · run {data['trace']['run_id']}</title>"
            in doc)
    assert "0x5E000101" in doc and str(0x5E000101) not in doc
    decision = section(doc, "<h2>Decision</h2>")
    assert "<th>check run by (operator)</th><td>A. Inspector</td>" in decision
    assert "<th>work order</th><td>WO-4711</td>" in decision
    assert "σ (statistical) [mm]" in doc and "±1σ" not in doc
    us = [v["uncertainty_mm"] for v in data["verdict"].values() if v["uncertainty_mm"] is not None]
    for v in plus_minus_values(text_of(doc)):
        assert any(v == f"{u:.{len(v.split('.')[1])}f}" for u in us), v
