"""``emacheck profile check``: an actuation profile, its signal map and every node's EDS checked together, offline.

Nothing is sent on any bus: the profile is loaded, every node's EDS is read
and the rig is planned (:func:`hil.profile.rig.plan_for`, the same check ``run`` and
``dry-run`` make before their first frame). It prints the nodes, how each EMA
holds a force, the PDO layout (COB-IDs, transmission types, the objects in
each PDO), the bus load and the notes; or every problem with its profile key
and object. Exit 0 when the profile can run, 3 on any problem.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rich import box
from rich.markup import escape
from rich.table import Table

from hil.cli.args import ExitCode, add_eds_arg, add_parser
from hil.cli.console import make_console


def _layout_rows(rig) -> list[dict]:
    rows = []
    for n in rig.plan.nodes:
        for p in n.layout.pdos:
            rows.append({"node": n.spec.name, "node_id": n.spec.node_id, "pdo": p.name, "cob_id": f"0x{p.cob_id:03X}",
                         "transmission": p.transmission_type, "bytes": p.length_bytes,
                         "fixed_by_eds": not p.write_mapping,
                         "objects": [f"0x{e.index:04X}:{e.subindex:02X} {e.name}" for e in p.entries]})
    return rows


def plan_json(rig) -> dict:
    """The planned rig as data (``--json``)."""
    plan = rig.plan
    return {"ok": True,
            "nodes": [{"name": n.spec.name, "node_id": n.spec.node_id, "role": n.spec.role.value,
                       "eds": str(rig.eds_paths[n.spec.name]), "device_profile": n.spec.device_profile,
                       "vendor_id": f"0x{n.spec.vendor_id:08X}", "product_code": f"0x{n.spec.product_code:08X}",
                       "disabled_pdos": [f"0x{c:04X}" for c, _ in n.layout.disable]} for n in plan.nodes],
            "force_control": {f"ema{d.ema}": d.force_control.value for d in plan.drives},
            "reaction_to_master_loss": {f"ema{d.ema}": d.reaction for d in plan.drives},
            "pdos": _layout_rows(rig),
            "bus_load": {"nominal": round(plan.load.load_nominal, 4), "worst": round(plan.load.load_worst, 4),
                         "event_bits_worst": plan.load.event_bits_worst},
            "notes": list(plan.notes)}


def cmd_profile_check(args: argparse.Namespace) -> int:
    """``emacheck profile check PROFILE.toml [--eds PATH] [--check CHECK.toml]``."""
    from hil.canopen.plan import PlanError
    from hil.check.resolution import sensor_steps, step_problems
    from hil.errors import ProfileError
    from hil.profile.load import load_actuation, load_check
    from hil.profile.rig import plan_for

    console = make_console()
    try:
        act = load_actuation(args.profile_file)
        check = load_check(args.check, act, args.profile_file)
        rig = plan_for(act, args.profile_file, args.eds)
        steps = sensor_steps(rig.plan, act, check)
        if bad := step_problems(rig.plan, act, check):
            raise PlanError(bad)
    except PlanError as exc:
        if args.json:
            print(json.dumps({"ok": False, "problems": [{"key": p.key, "object": p.obj, "message": p.message}
                                                        for p in exc.problems]}, indent=1))
        else:
            console.print(f"[red]{escape(str(args.profile_file))}: {len(exc.problems)} problem(s); "
                          f"nothing was sent on any bus[/red]", soft_wrap=True)  # a long path: one line
            for p in exc.problems:
                console.print(f"  [bold]{escape(p.key)}[/bold]" + (f" {escape(p.obj)}" if p.obj else "")
                              + f": {escape(p.message)}", soft_wrap=True)
        return ExitCode.INPUT
    except ProfileError as exc:
        if args.json:
            print(json.dumps({"ok": False, "problems": [{"key": _field_of(p), "object": None, "message": p}
                                                        for p in exc.problems]}, indent=1))
            return ExitCode.INPUT
        raise
    if args.json:
        print(json.dumps(plan_json(rig) | {"sensor_steps": [_step_json(s) for s in steps]}, indent=1))
        return ExitCode.PASS
    _print_plan(console, act, rig, args.profile_file)
    _print_steps(console, steps, check)
    console.print("[green]profile OK[/green]: `emacheck run` and `emacheck dry-run` make the same check before their "
                  "first frame")
    return ExitCode.PASS


def cmd_profile_apply_patch(args: argparse.Namespace) -> int:
    """``emacheck profile apply-patch PROFILE.toml PATCH.toml --out NEW.toml``: the profile with the patch's
    keys set, written as a new file once the patched profile loads and plans (its EDS looked up next to NEW)."""
    from hil.profile.patch import apply_patch, patch_problem, read_patch, toml_text
    from hil.profile.tables import read_toml
    from hil.record.outputs import utc_iso
    from hil.record.runfolder import create_bytes

    console = make_console()
    src, out = args.profile_file, args.out
    data, patch = read_toml(src), read_patch(args.patch_file)
    new = apply_patch(data, patch, src.name)
    if (why := patch_problem(data, patch, out, args.eds, out.name)) is not None:
        console.print(f"[red]the patched profile is refused; nothing written:[/red] {escape(why)}", soft_wrap=True)
        return ExitCode.INPUT
    head = f"# {src.name} patched with {args.patch_file.name} by emacheck profile apply-patch, {utc_iso()}\n"
    create_bytes(out, (head + toml_text(new)).encode())  # never over an existing file (OutputError, exit 3)
    old = dict(_leaves(data))
    for k, v in patch.items():
        console.print(escape(f"  {k}: {old.get(k, '(not set)')} -> {v}"), soft_wrap=True)
    console.print(f"[green]written[/green] {escape(str(out))} ({len(patch)} key(s) changed; it loads and plans)")
    return ExitCode.PASS


def _leaves(tables: dict):
    from hil.profile.patch import dotted

    return dotted(tables).items()


def _step_json(s) -> dict:
    return {"key": s.key, "sensor": s.what, "unit": s.unit, "step": s.step, "noise_sigma": s.sigma,
            "noise_key": s.noise_key, "largest_step": s.largest, "ok": s.ok}


def _print_steps(console, steps, check) -> None:
    tab = Table(title=f"sensor steps against their noise (frozen after safety.max_frozen_cycles = "
                      f"{check.safety.max_frozen_cycles} repeats)", box=box.SIMPLE_HEAD, pad_edge=False)
    for col in ("sensor", "key", "step", "noise sigma", "largest step that works"):
        tab.add_column(col)
    for s in steps:
        tab.add_row(s.what, s.key, f"{s.step:.3g} {s.unit}", f"{s.sigma:.3g} {s.unit}", f"{s.largest:.3g} {s.unit}")
    console.print(tab)


def _field_of(message: str) -> str | None:
    """The profile key a loader's problem names (``field 'safety.max_force_N'``), if it names one."""
    import re

    m = re.search(r"fields? '([^']+)'", message)
    return m.group(1) if m else None


def _print_plan(console, act, rig, path: Path) -> None:
    plan = rig.plan
    c = act.canopen
    console.print(f"[bold]{escape(str(path))}[/bold]: {escape(act.name)}")
    nodes = Table(title="nodes", box=box.SIMPLE_HEAD, pad_edge=False)
    for col in ("node", "id", "role", "EDS", "identity expected", "heartbeat ms"):
        nodes.add_column(col)
    for n in plan.nodes:
        s = n.spec
        nodes.add_row(s.name, str(s.node_id), f"{s.role.value} (CiA {s.device_profile})",
                      escape(str(rig.eds_paths[s.name])),
                      f"vendor 0x{s.vendor_id:08X}, product 0x{s.product_code:08X}, rev >= 0x{s.revision_min:08X}",
                      f"{s.heartbeat_period_s * 1e3:g}")
    console.print(nodes)
    for d in plan.drives:
        how = ("its CST mode (0x6071, per mille of the rated torque)" if d.force_control.value == "cst"
               else "the master's force loop on the measured force, commanding positions in CSP")
        react = ("consumer heartbeat 0x1016:01 and abort connection option 0x6007 configured, then drilled"
                 if d.reaction else f"none configured: canopen.external_watchdog = {c.external_watchdog!r}")
        console.print(f"EMA {d.ema}: holds forces by {how}; reaction to the master's death: {react}")
    if c.skip_master_loss_drill:
        console.print(f"[yellow]the master's-death drill is skipped:[/yellow] {escape(c.skip_master_loss_drill)}")
    tab = Table(title="PDO layout", box=box.SIMPLE_HEAD, pad_edge=False)
    for col in ("node", "PDO", "COB-ID", "transmission", "bytes", "objects"):
        tab.add_column(col)
    for r in _layout_rows(rig):
        trans = {1: "every SYNC", 255: "on a change"}.get(r["transmission"], str(r["transmission"]))
        tab.add_row(r["node"], r["pdo"] + (" (fixed)" if r["fixed_by_eds"] else ""), r["cob_id"], trans,
                    str(r["bytes"]), escape(", ".join(r["objects"])))
    console.print(tab)
    for n in plan.nodes:
        if n.layout.disable:
            console.print(f"{n.spec.name}: PDOs its EDS enables that the check does not use are disabled: "
                          + ", ".join(f"0x{i:04X}" for i, _ in n.layout.disable))
    ld = plan.load
    console.print(f"bus load at {c.bitrate_bps} bit/s, SYNC every {act.timing.sync_period_s * 1e3:g} ms: "
                  f"{ld.load_nominal:.1%} nominal, {ld.load_worst:.1%} worst case (limit 50 %)")
    for note in plan.notes:
        console.print(f"[yellow]note:[/yellow] {escape(note)}", soft_wrap=True)


def register(sub) -> None:
    p = add_parser(sub, "profile", handler=lambda a: p.print_help() or ExitCode.INPUT,
                   help="check an actuation profile against its drives' EDS files (offline)",
                   description="Actuation profiles: `emacheck profile check PROFILE.toml [--eds PATH]` checks "
                               "the profile, its signal map and every node's EDS together, offline.")
    ps = p.add_subparsers(dest="profile_cmd", metavar="check|apply-patch", parser_class=type(p))
    c = ps.add_parser("check", help="validate profile, signal map and EDS files together; print the PDO layout",
                      description="Validate an actuation profile, its signal map and every node's EDS together "
                                  "without touching a bus: print the nodes, how each EMA holds a force, the PDO "
                                  "layout (COB-IDs, transmission types, objects), the bus load and notes, or every "
                                  "problem with its profile key and object. Exit 0 when the profile can run, 3 on "
                                  "any problem (docs/drives.md).")
    c.add_argument("profile_file", metavar="PROFILE.toml", type=Path, help="the actuation profile")
    add_eds_arg(c)
    c.add_argument("--check", type=Path, default=None, metavar="CHECK.toml",
                   help="the check profile whose limits the sensors are judged against (default: the shipped one); "
                        "a quantised LVDT or load cell the check would stop on as frozen is a problem")
    c.add_argument("--json", action="store_true", help="print the layout (or the problems) as JSON")
    c.set_defaults(handler=cmd_profile_check)
    a = ps.add_parser("apply-patch", help="apply a profile patch (emacheck commission's profile.patch.toml)",
                      description="Write PROFILE.toml with the keys of PATCH.toml set (the patch emacheck commission "
                                  "writes: the keys and values that make the rig ready) as a new file --out, once "
                                  "the patched profile loads and plans with its EDS files (looked up next to --out). "
                                  "Comments are not kept. Exit 0 written, 3 refused (nothing written).\n\n"
                                  "  emacheck profile apply-patch my-rig.toml runs/c1/profile.patch.toml "
                                  "--out my-rig-2.toml")
    a.add_argument("profile_file", metavar="PROFILE.toml", type=Path, help="the actuation profile judged")
    a.add_argument("patch_file", metavar="PATCH.toml", type=Path, help="the patch (profile.patch.toml)")
    a.add_argument("--out", required=True, type=Path, metavar="NEW.toml", help="the patched profile (a new file)")
    add_eds_arg(a)
    a.set_defaults(handler=cmd_profile_apply_patch)
