"""Benchmark: ``emacheck diagnose NEW --reference HEALTHY`` on pairs of the independent rig's recordings vs keys.

The independent rig's effect-free recordings (../shared/data/independent-rig: ``null-a/b/c``,
``pitch-a/b``) are five draws of one rig model written independently of sim/, each with its own
internal play and contact stiffness per EMA, its own external play and LVDT pitch and offset, all in
``keys.json``. Compared two at a time (each pair once, the later name against the earlier as reference),
the true change of every keyed parameter is known; the rig model's external stiffness is one number,
the same in every recording (so the true compliance change is 0), and its external play one number (so
only the sum of our model's two bearing plays has a truth).

A keyed change is judged (:func:`judge`): at least twice its floor, it must be named, with the right
sign and within 30 % of the truth (or within the floor, where that is larger); at most half its floor, it
must not be named; in between either is right. The bearing plays one by one must never be named (not
separable: their split is not in the data). The frictions have no key and are reported, not judged.

    python tests/bench/bench_diagnose_independent_pairs.py /tmp/indep-pairs.json

(about 2 min on one core: five diagnoses, then ten comparisons; then each of the twelve recordings with
library effects against null-a, judged by :func:`judge_effect`). Prints a table per pair.
"""

from __future__ import annotations

import json
import sys
import time
from itertools import combinations
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]

from support.independent_rig import DATA, KEYS, rig_profile  # noqa: E402

RECORDINGS = ("null-a", "null-b", "null-c", "pitch-a", "pitch-b")


def truth_changes(new: str, ref: str) -> dict:
    """{parameter of diagnosis.json ``changes``: true change in its unit} from the keys."""
    kn, kr = KEYS[new], KEYS[ref]
    tn, tr = kn["truth"], kr["truth"]
    out = {"external_play_mm": 1000 * (tn["backlash_mm"]["ext"] - tr["backlash_mm"]["ext"])}
    for e in (1, 2):
        out[f"backlash_int{e}_mm"] = 1000 * (tn["backlash_mm"][f"int{e}"] - tr["backlash_mm"][f"int{e}"])
        out[f"stiffness_int{e}_N_per_mm"] = 100 * (tn["stiffness_N_per_mm"][f"int{e}"]["compression"]
                                                   / tr["stiffness_N_per_mm"][f"int{e}"]["compression"] - 1)
        out[f"lvdt_pitch{e}"] = 100 * (kn["lvdt_pitch"][e - 1] / kr["lvdt_pitch"][e - 1] - 1)
        out[f"lvdt_offset{e}_mm"] = 1000 * (kn["lvdt_offset_mm"][e - 1] - kr["lvdt_offset_mm"][e - 1])
        same = tn["stiffness_N_per_mm"]["ext"]["approx"] == tr["stiffness_N_per_mm"]["ext"]["approx"]
        if same:
            out[f"compliance_ext{e}_mm_per_N"] = 0.0
    return out


def judge(change: dict, truth: float | None) -> tuple[bool | None, str]:
    """(right?, why) of one comparison against its true change (None: no key, not judged)."""
    p = change["parameter"]
    if p.startswith("backlash_bearing"):
        return (not change["named"] and not change.get("separable", True),
                "one bearing's play: must be listed not separable, never named")
    if truth is None:
        return None, "no key"
    floor, est, named = change["floor"], change["change"], change["named"]
    if abs(truth) >= 2 * floor:
        ok = named and est * truth > 0 and abs(est - truth) <= max(0.3 * abs(truth), floor)
        return ok, f"true {truth:+.4g} >= 2 x floor: named, right sign, within 30 % (or the floor)"
    if abs(truth) <= floor / 2:
        return not named, f"true {truth:+.4g} <= floor/2: not named"
    return True, f"true {truth:+.4g} near the floor: either"


def run_pairs(recordings=RECORDINGS, cache: dict | None = None) -> list:
    """Every pair's comparison with its judgement: [{"new", "ref", "verdict", "rows": [...]}]."""
    from hil.analysis.diagnose.dual_reference import dual_reference_diagnosis
    cache = {} if cache is None else cache  # each recording's fit, by path (dual_reference_diagnosis)
    out = []
    for ref, new in combinations(recordings, 2):
        t0 = time.process_time()
        data, _ = dual_reference_diagnosis(DATA / f"{new}.csv.gz", DATA / f"{ref}.csv.gz", rig_profile(),
                                           cache=cache)
        truth = truth_changes(new, ref)
        rows = []
        for c in data["changes"]:
            if c.get("source") == "library":
                continue
            ok, why = judge(c, truth.get(c["parameter"]))
            rows.append({"parameter": c["parameter"], "where": c["where"], "unit": c["unit"],
                         "change": c["change"], "truth": truth.get(c["parameter"]), "floor": c["floor"],
                         "named": c["named"], "separable": c.get("separable", True), "ok": ok, "why": why})
        lib = [{"parameter": c["parameter"], "where": c["where"], "change": c["change"], "named": c["named"]}
               for c in data["changes"] if c.get("source") == "library"]
        out.append({"new": new, "ref": ref, "verdict": data["verdict"], "rows": rows, "library": lib,
                    "named": [(e["name"], e["where"]) for e in data["effects"]], "cpu_s": time.process_time() - t0})
    return out


def judge_effect(expect: list, changes: list) -> tuple[bool, str]:
    """An effect recording against an effect-free one: every expected library effect ``[name, where]`` has
    its change named at that place, or supported and under its floor (the words say which); no library
    change named anywhere else. (The recordings' nominal parameters differ too: judged by :func:`judge`.)"""
    lib = [c for c in changes if c.get("source") == "library" and not c.get("shape")]
    named = {(c["effect"], c["where"]) for c in lib if c["named"]}
    why = []
    for name, where in (tuple(e) for e in expect):
        mine = [c for c in lib if (c["effect"], c["where"]) == (name, where)]
        if (name, where) in named:
            why.append(f"{name} at {where} named")
        elif mine and any(c["supported"] and not c["above_floor"] and c["change"] > 0 for c in mine):
            why.append(f"{name} at {where} supported, under its floor")
        else:
            return False, f"{name} at {where} neither named nor supported under its floor"
    extra = named - {tuple(e) for e in expect}
    if extra:
        return False, f"named where no key has it: {sorted(extra)}"
    return True, "; ".join(why)


def run_effect_pairs(reference: str = "null-a", only: tuple | None = None, cache: dict | None = None) -> list:
    """Each effect recording of the library (keys' ``expect`` without ``unexplained``; ``only`` these) against
    ``reference``: [{"new", "ref", "expect", "named", "ok", "why", "keyed_wrong"}]."""
    from hil.analysis.diagnose.dual_reference import dual_reference_diagnosis
    cache = {} if cache is None else cache  # each recording's fit, by path (dual_reference_diagnosis)
    out = []
    for new, k in KEYS.items():
        if not k["expect"] or k["expect"][0][0] == "unexplained" or (only is not None and new not in only):
            continue
        data, _ = dual_reference_diagnosis(DATA / f"{new}.csv.gz", DATA / f"{reference}.csv.gz", rig_profile(),
                                           cache=cache)
        ok, why = judge_effect(k["expect"], data["changes"])
        truth = truth_changes(new, reference)
        keyed_wrong = [c["parameter"] for c in data["changes"] if c.get("source") != "library"
                       and judge(c, truth.get(c["parameter"]))[0] is False]
        lib = [(c["parameter"], c["where"], c["change"], c["unit"], c["floor"], c["z"], c["named"])
               for c in data["changes"] if c.get("source") == "library" and not c.get("shape")]
        out.append({"new": new, "ref": reference, "expect": k["expect"], "library": lib,
                    "named": [(e["name"], e["where"]) for e in data["effects"]], "ok": ok, "why": why,
                    "keyed_wrong": keyed_wrong})
    return out


def run_unexplained_pairs(reference: str = "null-a", cache: dict | None = None) -> list:
    """Each recording with physics outside the library (keys' ``["unexplained", "emaN"]``) against ``reference``:
    right when the comparison's verdict is ``unexplained`` located first at emaN (its own diagnosis has the
    mismatch, the reference's not)."""
    from hil.analysis.diagnose.dual_reference import dual_reference_diagnosis
    cache = {} if cache is None else cache  # each recording's fit, by path (dual_reference_diagnosis)
    out = []
    for new, k in KEYS.items():
        if not k["expect"] or k["expect"][0][0] != "unexplained":
            continue
        data, _ = dual_reference_diagnosis(DATA / f"{new}.csv.gz", DATA / f"{reference}.csv.gz", rig_profile(),
                                           cache=cache)
        ema = k["expect"][0][1]
        ok = data["verdict"] == "unexplained" and data["where"][:1] == [ema]
        out.append({"new": new, "ref": reference, "expect": ema, "verdict": data["verdict"], "where": data["where"],
                    "named": [(e["name"], e["where"]) for e in data["effects"]], "ok": ok})
    return out


def main(argv: list[str]) -> int:
    out = Path(next((a for a in argv if a.endswith(".json")), "bench_diagnose_independent_pairs.json"))
    if not (DATA / "keys.json").exists():
        print(f"independent-rig recordings not present at {DATA}")
        return 0
    cache: dict = {}  # one fit per recording for all three parts
    pairs = run_pairs(cache=cache)
    judged = right = 0
    for p in pairs:
        print(f"\n{p['new']} against {p['ref']}: {p['verdict']} ({p['cpu_s']:.0f} s CPU)")
        print("| parameter | where | change | true | unit | floor | named | judged |")
        print("|---|---|---|---|---|---|---|---|")
        for r in p["rows"]:
            t = "-" if r["truth"] is None else f"{r['truth']:+.4g}"
            j = "-" if r["ok"] is None else ("right" if r["ok"] else "WRONG")
            name = "not separable" if not r["separable"] else ("named" if r["named"] else "no")
            print(f"| {r['parameter']} | {r['where']} | {r['change']:+.4g} | {t} | {r['unit']} | {r['floor']:g} "
                  f"| {name} | {j} |")
            if r["ok"] is not None:
                judged += 1
                right += bool(r["ok"])
        for r in p["library"]:
            print(f"| {r['parameter']} (library) | {r['where']} | {r['change']:+.4g} | - | | | "
                  f"{'named' if r['named'] else 'no'} | - |")
    print(f"\njudged comparisons right: {right} of {judged} over {len(pairs)} pairs")
    eff = run_effect_pairs(cache=cache)
    print("\n| recording against null-a | expected | library changes (change unit, floor, z) | named | right |")
    print("|---|---|---|---|---|")
    for p in eff:
        lib = "; ".join(f"{n} at {w} {c:+.3g} {u} (floor {f:g}, z {z:.1f}){' NAMED' if nm else ''}"
                        for n, w, c, u, f, z, nm in p["library"])
        exp = ", ".join(f"{n} at {w}" for n, w in p["expect"])
        print(f"| {p['new']} | {exp} | {lib} | {p['why']} | {'yes' if p['ok'] and not p['keyed_wrong'] else 'NO'} |")
    right_e = sum(p["ok"] and not p["keyed_wrong"] for p in eff)
    print(f"\neffect recordings right: {right_e} of {len(eff)}")
    une = run_unexplained_pairs(cache=cache)
    for p in une:
        print(f"{p['new']} against null-a: {p['verdict']} at {p['where']} (expected unexplained at {p['expect']}); "
              f"named {p['named']}: {'right' if p['ok'] else 'WRONG'}")
    out.write_text(json.dumps({"pairs": pairs, "right": right, "judged": judged, "effect_pairs": eff,
                               "effect_right": right_e, "unexplained_pairs": une}, indent=1) + "\n")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
