"""The report an inspector signs, issue 47 part 5: page 1 says when, with which software and which run; every
printed page carries the run id and a page number; tables are not split over pages; a sign-off without the
actuators' identity says so; an aborted check lists where each drive was left; identity texts have a stated
length limit and wrap in the sign-off box.

Fast: the report's text from a synthetic result (tests/test_report_signoff.py's); slow: one dry-run aborted by an
over-current EMCY of EMA 1, its result.json (schema-checked) and its report."""

from __future__ import annotations

import json
import re
from importlib import resources

import jsonschema
import pytest
from test_report_signoff import make_result, text_of

from hil.cli import build_parser, main
from hil.profile.config import IDENTITY_MAX_CHARS
from hil.report import shell
from hil.report.maint import head_parts

RUN_ID = "f89b331810fb45fe8eae7d854c1eeafe"


def first_page(result: dict) -> str:
    """The report's page 1 as head_parts lays it out: from the heading to the end of the sign-off block."""
    doc = "\n".join(head_parts(result, "<p>intro</p>"))
    return doc[:doc.index("</div>", doc.index("<div class='signoff'>")) + len("</div>")]


# ---------------------------------------------------------------------------- page 1


def test_page_one_says_when_which_software_and_which_run():
    page = text_of(first_page(make_result()))
    assert "Check started 2026-11-26 13:55:58 UTC, analysed 2026-11-26 13:56:09 UTC" in page
    assert "software emacheck 0.1.0" in page and f"run {RUN_ID}." in page
    # before the decision, under the heading
    head = text_of(first_page(make_result()).split("<h2>Decision</h2>")[0])
    assert "2026-11-26 13:55:58 UTC" in head and "emacheck 0.1.0" in head and RUN_ID in head


def test_page_one_names_both_versions_where_the_analysis_is_newer():
    result = make_result()
    result["trace"]["software"] = {"name": "emacheck", "version": "0.2.0", "check_run_with": "0.1.0"}
    assert "software emacheck 0.1.0 (the check), 0.2.0 (this analysis)" in text_of(first_page(result))


def test_page_one_of_a_bare_recording_says_what_it_lacks():
    result = make_result(run_id=None, mode=None, recording="/data/flight-042.csv", files={"recording": "a3" * 32})
    result["trace"]["started_utc"] = None
    page = text_of(first_page(result))
    assert "Check date and time not recorded (a recording without its run folder)" in page
    assert "no run id (a recording without its run folder)" in page and "software emacheck 0.1.0" in page


# ---------------------------------------------------------------------------- every printed page


def test_every_printed_page_has_a_running_header_and_footer_with_the_run_id(tmp_path):
    result = make_result()
    out = tmp_path / "r.html"
    shell.write_page(out, shell.page_title("emacheck maintenance check", result), head_parts(result, ""),
                     shell.running_head("emacheck maintenance check", result))
    doc = out.read_text()
    running = f"emacheck maintenance check: PASS · run {RUN_ID} · emacheck 0.1.0"
    assert (f"<table class='sheet'><thead><tr><td>{running}</td></tr></thead>"
            f"<tfoot><tr><td>{running}</td></tr></tfoot><tbody><tr><td>") in doc
    assert doc.endswith("</td></tr></tbody></table></body></html>")
    # the title, which the browsers' own print header shows, carries the run id too
    assert f"<title>emacheck maintenance check: PASS · run {RUN_ID}</title>" in doc


def test_the_running_header_of_a_bare_recording_names_its_file_and_hash():
    result = make_result(run_id=None, mode=None, recording="/data/flight-042.csv", files={"recording": "a3" * 32})
    assert shell.running_head("emacheck maintenance check", result) == (
        "emacheck maintenance check: PASS · no run id; file flight-042.csv, sha256 a3a3a3a3a3a3a3a3… · emacheck 0.1.0")


def test_print_css_repeats_header_footer_and_table_headers_and_numbers_pages():
    css = shell.CSS
    screen, printed = css[:css.index("@media print")], css[css.index("@media print"):]
    # on screen the running lines are hidden and the sheet is a plain block
    assert ".sheet>thead,.sheet>tfoot{display:none}" in screen
    # printed: the sheet is a table whose header and footer groups every browser repeats on each page
    assert ".sheet>thead{display:table-header-group}.sheet>tfoot{display:table-footer-group}" in printed
    assert re.search(r"table\.sheet\{display:table;[^}]*break-inside:auto\}", printed)
    # page numbers in the page's margin box (Chromium prints them; docs/report.md says who does not)
    assert '@bottom-right{content:"page " counter(page) " of " counter(pages)' in css
    # a table's header repeats where a long table is split; no table is split otherwise
    assert "thead{display:table-header-group}" in printed
    assert re.search(r"table,\.signoff,figure,tr,section\.keep\{page-break-inside:avoid;break-inside:avoid\}",
                     printed)
    assert "table.long{page-break-inside:auto;break-inside:auto}" in printed


@pytest.mark.parametrize("rows,long", [(shell.LONG_TABLE_ROWS - 1, False), (shell.LONG_TABLE_ROWS, True)])
def test_a_table_splits_between_rows_only_from_its_row_limit(rows, long):
    html = shell.table(["item", "value"], [[f"r{i}", i] for i in range(rows)])
    assert html.startswith("<table class='long'><thead>" if long else "<table><thead>")
    assert html.count("<tr>") == rows + 1 and "<thead><tr><th>item</th><th>value</th></tr></thead><tbody>" in html


def test_the_traceability_table_is_one_unsplit_table_with_its_header_in_thead():
    html = shell.trace_lines(make_result()["trace"])
    assert html.count("<table") == 1 and "<table class='items'><thead><tr><th>item</th><th>value</th>" in html


# ---------------------------------------------------------------------------- identity in the sign-off


def bare(**trace) -> dict:
    """A result of `analyze flight.csv`: no run, no drive identity, no aircraft."""
    result = make_result(run_id=None, mode=None, recording="/data/flight-042.csv", files={"recording": "a3" * 32})
    result["trace"].update({"identity": {}, "aircraft": None, "position": None, "flight_hours": None, **trace})
    return result


def test_a_bare_recording_sign_off_says_the_actuators_are_not_identified():
    block = shell.signoff_block(bare())
    words = text_of(block)
    assert "Actuators not identified." in words
    assert ("it records no serial number of EMA 1, serial number of EMA 2, aircraft. It was analysed from a "
            "recording file alone") in words
    assert "read each actuator's serial number off its identification plate" in words
    assert "do not sign for an actuator that has not been identified" in words
    for k in (1, 2):
        assert f"<tr><th>EMA {k} serial number (from its plate)</th><td class='line'></td></tr>" in block
    assert "<tr><th>aircraft and position</th><td class='line'></td></tr>" in block
    assert block.count("<td class='line'></td>") == 3 + 3  # the unknowns, then inspector, date, signature


def test_one_serial_not_read_is_named_alone():
    result = make_result()
    result["trace"]["identity"]["ema2"]["serial"] = None
    block = shell.signoff_block(result)
    assert "it records no serial number of EMA 2." in text_of(block)
    assert "did not report it when the check read their identity (object 0x1018)" in text_of(block)
    assert "EMA 1 serial number (from its plate)" not in block and "EMA 2 serial number (from its plate)" in block


def test_an_identified_check_has_no_such_words():
    block = shell.signoff_block(make_result())
    assert "not identified" not in block and "from its plate" not in block and "aircraft and position" not in block
    # an unknown aircraft alone: a line to fill in, no alarm
    result = make_result()
    result["trace"]["aircraft"] = None
    block = shell.signoff_block(result)
    assert "not identified" not in block and "<tr><th>aircraft and position</th>" in block


# ---------------------------------------------------------------------------- identity texts: length


@pytest.mark.parametrize("option", ["--aircraft", "--position", "--rig", "--operator", "--work-order"])
def test_identity_texts_at_the_limit_pass_one_more_is_exit_3(option, capsys, tmp_path):
    assert IDENTITY_MAX_CHARS == 64
    ok = build_parser().parse_args(["dry-run", option, "W" * IDENTITY_MAX_CHARS])
    assert getattr(ok, option[2:].replace("-", "_")) == "W" * IDENTITY_MAX_CHARS
    out = tmp_path / "never"
    with pytest.raises(SystemExit) as e:
        main(["dry-run", "--out", str(out), option, "W" * (IDENTITY_MAX_CHARS + 1)])
    assert e.value.code == 3
    err = capsys.readouterr().err
    assert f"argument {option}: 65 characters; an identity text is at most 64" in err
    assert not out.exists()


def test_the_history_filter_on_an_aircraft_has_the_same_limit(capsys):
    """``history --aircraft`` looks up what a check recorded: no recorded text is longer than 64 characters."""
    ok = build_parser().parse_args(["history", "--aircraft", "W" * IDENTITY_MAX_CHARS])
    assert ok.aircraft == "W" * IDENTITY_MAX_CHARS
    with pytest.raises(SystemExit) as e:
        main(["history", "--aircraft", "W" * (IDENTITY_MAX_CHARS + 1)])
    assert e.value.code == 3
    assert "argument --aircraft: 65 characters; an identity text is at most 64" in capsys.readouterr().err


@pytest.mark.parametrize("n,ok", [(IDENTITY_MAX_CHARS, True), (IDENTITY_MAX_CHARS + 1, False)])
def test_the_profiles_identity_texts_have_the_same_limit(tmp_path, n, ok):
    from hil.errors import ProfileError
    from hil.profile.load import load_actuation
    from support.profiles import write_profile_variant

    path = write_profile_variant("actuation.toml", tmp_path / "a.toml", {"history": {"position": "p" * n}})
    if ok:
        assert load_actuation(path).history.position == "p" * n
    else:
        with pytest.raises(ProfileError, match=r"field 'history.position' is 65 characters long; an identity text "
                                               r"is at most 64"):
            load_actuation(path)


def test_the_sign_off_box_wraps_long_words():
    assert re.search(r"\.signoff\{[^}]*overflow-wrap:anywhere", shell.CSS)
    assert re.search(r"\.signoff table\{[^}]*table-layout:fixed", shell.CSS)


# ---------------------------------------------------------------------------- an aborted check


@pytest.fixture(scope="module")
def aborted(tmp_path_factory):
    """A dry-run aborted by an over-current EMCY of EMA 1 at 2 s: its run folder, result.json and record."""
    from hil.cli.dry_run import dry_run
    from hil.profile.load import load_actuation, load_check, load_simrig
    from hil.record.runfolder import read_record
    from sim.faults import Fault

    act = load_actuation()
    r = dry_run(act, load_check(None, act), load_simrig(), tmp_path_factory.mktemp("abort") / "run",
                faults=[Fault("emcy_over_current", 1, 2.0)])
    assert r.exit_code == 2
    return r, json.loads((r.out / "result.json").read_text()), read_record(r.out), act


@pytest.mark.slow
def test_an_aborted_checks_result_says_where_each_drive_was_left(aborted):
    r, result, meta, act = aborted
    schema = json.loads(resources.files("hil.schemas").joinpath("result.schema.json").read_text())
    jsonschema.validate(result, schema)
    left = result["trace"]["drives_last"]
    assert sorted(left) == ["ema1", "ema2"]
    sig = [line.split(",") for line in (r.out / "signals.csv").read_text().splitlines()]
    t0, t_logged = float(sig[1][0]), float(sig[-1][0])
    for k, d in left.items():
        fin = meta.drives_final[k]
        assert (d["node"], d["state"], d["safe"], d["confirmed"], d["seen"]) == \
            (fin.node, fin.state, fin.safe, fin.confirmed, fin.seen)
        assert d["safe"] is True and d["state"] == "SWITCH_ON_DISABLED"
        # the last complete sample: no earlier than the last row logged, within the stop's time after it
        assert t_logged - t0 - 1e-9 <= d["t_s"] <= t_logged - t0 + act.canopen.enable_timeout_s
        assert abs(d["force_N"]) <= 8000.0 and abs(d["position_mm"]) <= 19.5 and abs(d["stroke_mm"]) <= 19.5
    # EMA 1's over-current EMCY, at the SYNC period it came in, within a cycle of the injected onset
    (e,) = [e for e in left["ema1"]["emcy"] if e["code"] == 0x2310]
    assert e["text"] == "over current" and left["ema1"]["emcy_count"] >= 1
    onset = r.injector.onset_s["emcy_over_current"] - t0
    assert onset - 1e-9 <= e["t_s"] <= onset + 2 * act.timing.sync_period_s
    assert not [e for e in left["ema2"]["emcy"] if e["code"] == 0x2310]


@pytest.mark.slow
def test_an_aborted_checks_report_lists_where_each_drive_was_left(aborted):
    r, result, _, _ = aborted
    doc = (r.out / "report.html").read_text()
    section = doc[doc.index("<h3>Where the drives were left</h3>"):]
    section = section[:section.index("</table>")]
    words = text_of(section)
    left = result["trace"]["drives_last"]
    for k, d in left.items():
        assert f"EMA {k[-1]} (node {d['node']})" in words
        assert f"{d['position_mm']:.3f}" in words and f"{d['force_N']:.0f}" in words
    assert words.count("Switch on disabled") == 2
    e = left["ema1"]["emcy"][-1]
    assert f"EMCY 0x{e['code']:04X} ({e['text']}) at t = {e['t_s']:.3f} s" in words
    # on page 1: after the abort's reason, before the evidence (2 s in: nothing to analyse, no decision)
    assert "<h2>Decision</h2>" not in doc and "No analysis: " in doc
    assert doc.index("Aborted: ") < doc.index("<h3>Where the drives were left</h3>") < doc.index("<h2>Traceability")


LEFT = {"ema1": {"node": 1, "state": "FAULT", "safe": False, "confirmed": True, "reachable": True,
                 "seen": "read after the stop at t = 52.310 s", "t_s": 52.104, "position_mm": 3.2512,
                 "stroke_mm": 3.4101, "force_N": 1203.4,
                 "emcy": [{"t_s": 52.1, "code": 0x2310, "error_register": 3, "text": "over current"}],
                 "emcy_count": 9},
        "ema2": {"node": 2, "state": "SWITCH_ON_DISABLED", "safe": True, "confirmed": True, "reachable": True,
                 "seen": "read after the stop at t = 52.310 s", "t_s": 52.104, "position_mm": -0.5, "stroke_mm": -0.4,
                 "force_N": -1187.0, "emcy": [], "emcy_count": 0}}


def test_an_aborted_report_with_an_analysis_says_where_the_drives_were_left_on_page_one():
    result = make_result()
    result.update(status="aborted", reason="error: DriveFault: node 1 (EMA 1): EMCY 0x2310 (over current)")
    result["trace"]["drives_last"] = LEFT
    page = first_page(result)
    assert page.index("Aborted: ") < page.index("<h3>Where the drives were left</h3>") < page.index("<h2>Decision")
    words = text_of(page[page.index("<h3>Where the drives were left</h3>"):page.index("<h2>Decision")])
    assert "EMA 1 (node 1)Faultread after the stop at t = 52.310 sNOT confirmed safe52.1043.2513.4101203" in words
    assert "EMCY 0x2310 (over current) at t = 52.100 s (the last 1 of 9)" in words
    assert "EMA 2 (node 2)Switch on disabled" in words and "yes52.104-0.500-0.400-1187none" in words
    assert "Where the drives were left" not in first_page(make_result())  # a check that ran to its end


def test_an_incomplete_report_says_the_drives_state_was_not_recorded():
    result = make_result()
    result.update(status="incomplete", reason="the run did not finish")
    words = text_of(first_page(result))
    assert "Where the drives were leftNot recorded: the check was cut off before its stop was recorded" in words


# ---------------------------------------------------------------------------- printed by real browsers


def printed_report(tmp_path) -> tuple:
    """A report of several pages: page 1, the traceability table, a 44-row table (moved whole) and a 70-row
    one (split between rows), written as write_page writes every report."""
    result = make_result()
    near = shell.table(["row", "value"], [[f"near-{i:02d}", i] for i in range(shell.LONG_TABLE_ROWS - 1)])
    long = shell.table(["long row", "value"], [[f"long-{i:02d}", i] for i in range(70)])
    parts = [*head_parts(result, "<p>intro</p>"), shell.trace_lines(result["trace"]), "<h2>Near</h2>", near,
             "<h2>Long</h2>", long]
    out = tmp_path / "report.html"
    shell.write_page(out, shell.page_title("emacheck maintenance check", result), parts,
                     shell.running_head("emacheck maintenance check", result))
    return out, result


def page_of(pages: list[str], text: str) -> int:
    (i,) = [i for i, p in enumerate(pages) if text in p]
    return i


def _print_or_skip(how, html, pdf):
    from support.printing import Missing

    try:
        return how(html, pdf)
    except Missing as exc:
        pytest.skip(str(exc))


@pytest.mark.slow
@pytest.mark.parametrize("browser", ["chromium", "firefox"])
def test_printed_every_page_carries_the_run_id_and_no_short_table_splits(tmp_path, browser):
    from support import printing

    html, _ = printed_report(tmp_path)
    pdf = tmp_path / f"{browser}.pdf"
    _print_or_skip(printing.chromium_pdf if browser == "chromium" else printing.firefox_pdf, html, pdf)
    pages = printing.pages(pdf)
    assert len(pages) >= 3
    for i, text in enumerate(pages, start=1):
        assert text.count(f"run {RUN_ID}") >= 2, f"page {i}: running header and footer"  # (header, footer)
        if browser == "chromium":  # the @page margin box; Firefox prints none (docs/report.md)
            assert f"page {i} of {len(pages)}" in text, i
    assert page_of(pages, "Traceability") == page_of(pages, "actuation (sha256)")
    assert page_of(pages, "near-00") == page_of(pages, f"near-{shell.LONG_TABLE_ROWS - 2:02d}")
    first, last = page_of(pages, "long-00"), page_of(pages, "long-69")
    assert last > first and all("long row" in pages[p] for p in range(first, last + 1))  # its header repeated
    assert page_of(pages, "check run by (operator)") == page_of(pages, "signature") == 0  # the sign-off, whole


# ---------------------------------------------------------------------------- the record of where drives were left


@pytest.mark.parametrize("sent", [8, 9])
def test_drive_last_from_a_sample_keeps_the_last_eight_emcys_and_counts_all(sent):
    from hil.canopen.process import Sample
    from hil.record.driveparts import EMCY_KEPT, DriveLast, last_known
    from hil.record.runrecord import RunRecord

    assert EMCY_KEPT == 8
    smp = Sample(t_s=52.118, phi1_rad=6.5, phi2_rad=-1.3, s1_mm=3.41, s2_mm=-0.4, F1_N=1203.4, F2_N=-1187.0)
    emcys = {"ema1": [{"t_s": 50.014 + 0.002 * i, "code": 0x2310, "error_register": 3, "text": "over current"}
                      for i in range(sent)], "ema2": []}
    last = DriveLast.of(smp, 0.014, 2.0, emcys)  # i_total 2 rad/mm
    one = last["ema1"]
    assert (one.t_s, one.position_mm, one.stroke_mm, one.force_N) == (52.104, 3.25, 3.41, 1203.4)
    assert last["ema2"].position_mm == -0.65 and last["ema2"].emcy == () and last["ema2"].emcy_count == 0
    assert len(one.emcy) == 8 and one.emcy_count == sent
    assert one.emcy[-1].t_s == pytest.approx(50.0 + 0.002 * (sent - 1)) and one.emcy[0].t_s == pytest.approx(
        50.0 + 0.002 * (sent - 8))
    assert one.emcy[-1].words() == f"EMCY 0x2310 (over current) at t = {50.0 + 0.002 * (sent - 1):.3f} s"
    # meta.json both ways; result.json's trace without CANopen drives (the plant): no state, the sample
    rec = RunRecord(run_id="x", drives_last=last)
    assert RunRecord.from_json(json.loads(json.dumps(rec.as_json()))) == rec
    known = last_known(None, last)
    assert known["ema1"]["state"] is None and known["ema1"]["safe"] is None and known["ema1"]["force_N"] == 1203.4
    assert "no CANopen drive: simulated plant" in text_of(shell.drives_left({"trace": {"drives_last": known}}))


def test_a_malformed_drives_last_is_refused_naming_its_field():
    from hil.errors import RunRecordError
    from hil.record.runrecord import RunRecord

    bad = {"drives_last": {"ema1": {"t_s": 1.0, "position_mm": "3", "stroke_mm": 0.0, "force_N": 0.0}}}
    with pytest.raises(RunRecordError, match=r"field 'drives_last.ema1.position_mm': expected a number"):
        RunRecord.from_json(bad)
