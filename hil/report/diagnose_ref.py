"""The report of ``emacheck diagnose NEW --reference HEALTHY`` with the dual-EMA model (``diagnosis_report.html``).

Per parameter: the reference's value, this recording's, the change with its expanded uncertainty
U (k = 2), the relevance floor and whether it is named; the library effects each recording's own
diagnosis accepted; and the fits before and after: the new recording's channels against the reference's
model, and against it with the named changes only.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hil.report.diagnose import coverage_paragraph, figure_residuals_pair
from hil.report.shell import column, esc, file_link, img, table, write_page


def _cap(text: str) -> str:
    """A sentence of diagnosis.json's words, its first letter upper case."""
    return text[:1].upper() + text[1:]


def _g(x, nd: int = 4) -> str:
    return "—" if x is None else f"{x:.{nd}g}"


def _status(c: dict) -> str:
    if c["named"]:
        return "<b>named</b>"
    if c.get("separable") is False:
        return "not separable by this check: not named"
    if c.get("shape"):
        return "shape parameter (form, not size): not named"
    if c["floor"] is None:
        return "no floor measured: not named"
    return "supported, under its floor" if c["supported"] else "not supported (|z| ≤ 3)"


def _value(c: dict, key: str) -> str:
    """A parameter's value on one recording in the change's unit where that is um (values in mm)."""
    return _g(c[key] * 1000.0, 6) + " um" if c.get("unit") == "um" else _g(c[key], 6)


def write_dual_reference_report(path: Path, data: dict, fits, *, json_name: str = "diagnosis.json") -> None:
    """Self-contained HTML in the report shell: the changes table, the floors, the fits before and after."""
    head = "changes named" if data["effects"] else "no change above its floor"
    rows = [[esc(c["parameter"]), esc(c["where"]), esc(c.get("source", "nominal")), _value(c, "reference"),
             _value(c, "value"), f"{_g(c['change'])} ± {_g(2.0 * c['uncertainty'], 2)}", esc(c.get("unit", "")),
             _g(c["floor"]), _g(c["z"], 3), _status(c)] for c in data["changes"]]
    cols = [column("parameter"), column("where"), column("kind"), column("reference"), column("now"),
            column("change ± U (k=2)"), column("unit of change"), column("floor"), column("z", "1"), column("status")]
    fl = data["floor"]
    kinds = ", ".join(f"{esc(k)} {_g(v)}" for k, v in fl["by_kind"].items())
    parts = [f"<h1>Dual-EMA check against a reference: <span class='badge pass'>{esc(head)}</span></h1>",
             f"<p>Reference {esc(data['reference']['recording'])}; verdict {esc(data['verdict'])}; "
             f"{_g(data.get('diagnosis_s'), 3)} s.</p>",
             "<h2>Parameters against the reference</h2>",
             "<p>Nominal parameters (fitted on both recordings) and the parameters of every library effect "
             "accepted on either recording (fitted on both). A change is named only when supported (|z| > "
             f"{_g(fl.get('z_min'))}) <b>and</b> above its floor. U = 2 u. "
             f"{esc(_cap(data['reference']['words']))}.</p>", table(cols, rows, raw=True),
             f"<h2>Floors</h2><p>{kinds} (play um; stiffness, sensor and load cell gain %; friction N). "
             f"{esc(_cap(fl['words']))}. Source: {esc(fl.get('source', 'the defaults'))}.</p>",
             coverage_paragraph(fl),
             "<h2>Library effects each recording's own diagnosis accepted</h2>",
             table([column("recording"), column("effects")],
                   [["this recording", esc(", ".join(f"{e['name']} at {e['where']}" for e in
                                                     data["effects_recording"]) or "none")],
                    ["reference", esc(", ".join(f"{e['name']} at {e['where']}" for e in
                                                data["effects_reference"]) or "none")]], raw=True)]
    if fits is not None and data.get("fits"):
        rms = data["fits"]
        parts += ["<h2>Fits before and after</h2>", f"<p>{esc(_cap(rms['words']))}.</p>",
                  table([column("channel"), column("unit"), column("RMS before"), column("RMS after")],
                        [[c, "N" if c.startswith("F") else "mm", _g(rms["before"][c]), _g(rms["after"][c])]
                         for c in fits.channels])]
        parts += [f"<h3>{esc(c)}</h3>" + img(figure_residuals_pair(
            fits.t_s, fits.measured[c], fits.valid[c], fits.before[c], fits.after[c], c,
            ("reference's model", "with the named changes"))) for c in fits.channels
            if np.asarray(fits.valid[c]).any()]
    parts.append(file_link(json_name))
    write_page(path, "diagnosis against a reference", parts)
