"""What ``emacheck commission`` leaves behind, each file written once into its folder: ``commission.json``
(schema ``hil/schemas/commission.schema.json``), ``commission.html``, the profile patch
``profile.patch.toml`` and a copy of each profile it judged (``judged-actuation.toml``,
``judged-check.toml``; of a rehearsal's simulated rig too, ``simulated-rig.toml``,
``simulated-rig-actuation.toml``), and the console's summary."""

from __future__ import annotations

from pathlib import Path

from hil.cli.commission_setup import ended_in
from hil.record.outputs import Outputs, utc_iso

__all__ = ["PATCH", "REPORT_HTML", "REPORT_JSON", "identities", "print_summary", "report_data", "write_outputs"]

#: The report's file names in the commissioning's folder.
REPORT_JSON, REPORT_HTML, PATCH = "commission.json", "commission.html", "profile.patch.toml"


def identities(act, rig, scan_nodes: dict) -> list[dict]:
    """Per node of the profile: the identity it expects (vendor, product, lowest revision, a pinned serial)
    and what the node reported (0x1018:01..04; None: not read)."""
    out = []
    for node in rig.plan.nodes:
        spec = node.spec
        read = (scan_nodes.get(spec.node_id) or {}).get("identity") or {}
        serial = getattr(act.canopen, f"serial_{spec.name}", 0) if spec.key == "canopen" else 0
        out.append({"node": spec.node_id, "name": spec.name,
                    "expected": {"vendor_id": spec.vendor_id, "product_code": spec.product_code,
                                 "revision_min": spec.revision_min, "serial": serial or None},
                    "read": {k: read.get(k) for k in ("vendor_id", "product_code", "revision", "serial")}})
    return out


def report_data(core, master, link, final: dict, context: dict, explanation, idents: list[dict]) -> dict:
    """The commissioning report as data (hil/schemas/commission.schema.json)."""
    from hil import __version__
    from hil.master.commission_rules import (
        DEAD_FRACTION,
        FORCE_GAIN_TOLERANCE,
        MIN_MOTION_FRACTION,
        MIN_STEP_MOTION_MM,
        NOISE_FACTOR,
        REST_S,
    )
    from hil.master.hypotheses import UNIT_NOISE_BAND
    from hil.profile.config import HARD_LVDT_GAIN_TOLERANCE

    findings = [f.as_json() for f in core.findings]
    measured = {k: v for k, v in core.measured.items() if not k.endswith("_raw")}
    return {
        "kind": "commission", "status": "not ready" if findings else "ready", "exit_code": None,
        "created": utc_iso(), "software": {"emacheck": __version__}, **context,
        "stage_reached": core.stage.value,
        "limits": core.lim.as_json(),
        "thresholds": {"rest_s": REST_S, "noise_factor": NOISE_FACTOR, "lvdt_gain_tolerance": HARD_LVDT_GAIN_TOLERANCE,
                       "force_gain_tolerance": FORCE_GAIN_TOLERANCE, "dead_fraction": DEAD_FRACTION,
                       "min_motion_fraction": MIN_MOTION_FRACTION, "min_step_motion_mm": MIN_STEP_MOTION_MM,
                       "max_frozen_cycles": core.check.safety.max_frozen_cycles, "unit_noise_band": UNIT_NOISE_BAND},
        "scan": {"heard": sorted(core.scan.heard), "nodes": {str(k): v for k, v in core.scan.nodes.items()}},
        "identity": {f"ema{d.ema}": ({"node": d.node_id, **d.identity} if d.identity else None)
                     for d in master.drives.values()},
        "identities": idents,
        # from the preflight's own record: the drill's outcome also when it refused the drives
        "master_loss": {f"ema{d.ema}": d.master_loss.as_json() for d in master.preflight.drives
                        if d.master_loss is not None},
        "measured": measured,
        "hypotheses": explanation.as_json(),
        "patch": {"file": PATCH, "keys": explanation.patch, "wiring_fixes": list(explanation.wiring)},
        "drives_final": final,
        "close_errors": list(link.close_errors),
        "stalls": link.stall_record(),  # the master loop's own stalls (as meta.json's), the PC's evidence
        "findings": findings,
    }


def write_outputs(out: Path, report: dict, traces: dict, T: float, paths: dict, copies: dict | None = None) -> None:
    """``commission.json``, ``commission.html``, the patch and a copy of each profile judged (``paths``:
    name -> file, None: the shipped one) and of each file of ``copies`` (its name in ``out`` -> file: the
    simulated rig's profiles, ``simulated-rig.toml`` and ``simulated-rig-actuation.toml``), every file created
    once."""
    from hil.profile.load import default_profile_path
    from hil.profile.patch import patch_text
    from hil.record.runfolder import create_bytes
    from hil.report.commission import write_commission_report

    outputs = Outputs(out)
    outputs.write_json(REPORT_JSON, report)
    outputs.write_with(REPORT_HTML, lambda p: write_commission_report(p, report, traces, T))
    for name, path in paths.items():
        src = Path(path) if path is not None else default_profile_path(f"{name}.toml")
        create_bytes(outputs.path(f"judged-{name}.toml"), src.read_bytes())
    for name, path in (copies or {}).items():
        create_bytes(outputs.path(name), Path(path).read_bytes())
    sha = report.get("files_sha256") or {}
    header = [f"emacheck commission {report['created']}: the keys of {paths.get('actuation') or '(shipped)'} "
              f"(sha256 {sha.get('actuation', '-')}) that make this rig ready",
              f"status {report['status']}; apply: emacheck profile apply-patch PROFILE.toml {PATCH} --out NEW.toml"]
    header += [f"wiring fix (no profile key): {w}" for w in report["patch"]["wiring_fixes"]]
    create_bytes(outputs.path(PATCH), patch_text(report["patch"]["keys"], header).encode())


def print_summary(console, report: dict, out: Path) -> None:
    """Every finding, the patch, the nodes' end states and the verdict on the console."""
    from rich.markup import escape

    for f in report["findings"]:
        fits = f" -> fits: {f['fits']}" if f["fits"] is not None else ""
        console.print(escape(f"  [{f['stage']}] {f['kind']}: {f['key'] or '-'}: {f['text']}{fits}"), soft_wrap=True)
    ours = {v["node"] for v in report["scan"]["nodes"].values()}
    if others := [n for n in report["scan"]["heard"] if n not in ours]:
        console.print(f"  note: node id(s) {', '.join(map(str, others))} answered and are not in the profile")
    if keys := report["patch"]["keys"]:
        console.print(escape(f"  patch ({out / PATCH}): " + "; ".join(f"{k} = {v}" for k, v in keys.items())),
                      soft_wrap=True)
    for w in report["patch"]["wiring_fixes"]:
        console.print(escape(f"  wiring fix: {w}"), soft_wrap=True)
    for ema, d in report["drives_final"].items():
        ident = (report["identity"].get(ema) or {}).get("serial")
        serial = f", serial 0x{ident:08X} (0x1018:04)" if ident else ""
        scanned = report["scan"]["nodes"].get(str(d["node"]), {})
        console.print(f"  {ema}: node {d['node']}{serial}, ended in {ended_in(d, scanned)}")
    word = "[green]READY[/green] for its first check" if report["status"] == "ready" else \
        f"[red]NOT READY[/red]: {len(report['findings'])} problem(s)"
    console.print(f"rig {word}; report {out / REPORT_HTML}")
