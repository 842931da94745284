"""Packing a node's PDOs: what the signal map needs of it, in the PDO records its EDS offers (pure).

Part of :mod:`hil.canopen.plan` (which documents the planning rules): :class:`PdoPacker` places each
needed object in a PDO (a mapping the EDS fixes used as it is, the rest first-fit into records the
master may map), gives every PDO its COB-ID and transmission type, lists the node's other enabled PDOs
for disabling, and checks the COB-IDs of the whole rig. Problems go to the planner's callback, each with
its profile key and object.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import canopen.objectdictionary as cod

from hil.canopen.frame import (
    EMCY_COB_ID_BASE,
    HEARTBEAT_COB_ID_BASE,
    NMT_COB_ID,
    SDO_RX_COB_ID_BASE,
    SDO_TX_COB_ID_BASE,
    SYNC_COB_ID,
)
from hil.canopen.od import lookup
from hil.canopen.pdo import (
    COB_ID_INVALID,
    COB_ID_NO_RTR,
    TYPE_BITS,
    Direction,
    MappedObject,
    PdoLayout,
    PdoSpec,
    predefined_cob_id,
)
from hil.canopen.signalmap import NodeSpec, SignalEntry, SignalMap

__all__ = ["EdsView", "Need", "PdoPacker", "RESTRICTED_CAN_IDS", "records"]

#: CiA 301 restricted CAN-IDs (may not be used by a PDO), inclusive ranges.
RESTRICTED_CAN_IDS = ((0x000, 0x000), (0x001, 0x07F), (0x101, 0x180), (0x581, 0x5FF),
                      (0x601, 0x67F), (0x6E0, 0x6FF), (0x701, 0x77F), (0x780, 0x7FF))
_PREFIX = {Direction.RX: "R", Direction.TX: "T"}


#: the most objects one PDO maps (CiA 301: sub-indices 1-64 of the mapping record, 64 one-bit objects)
MAX_MAPPED_OBJECTS = 64


class EdsView:
    """What the planner asks of one node's object dictionary."""

    def __init__(self, od: cod.ObjectDictionary, name: str) -> None:
        self.od = od
        self.name = name

    def var(self, index: int, subindex: int) -> cod.ODVariable | None:
        return lookup(self.od, index, subindex)

    def readable(self, index: int, subindex: int = 0) -> bool:
        v = self.var(index, subindex)
        return v is not None and v.readable

    def writable(self, index: int, subindex: int = 0) -> bool:
        v = self.var(index, subindex)
        return v is not None and v.writable

    def default(self, index: int, subindex: int = 0) -> int | float | None:
        v = self.var(index, subindex)
        return None if v is None else v.default


@dataclass
class _Record:
    """One PDO record (communication + mapping) of a node's EDS."""

    direction: Direction
    number: int
    n_entries: int
    mapping_writable: bool
    cob_writable: bool
    type_writable: bool
    default_cob: int | None
    default_type: int | None
    default_entries: tuple[tuple[int, int, int], ...]  # (index, subindex, bits)
    used: bool = False


def records(eds: EdsView, direction: Direction) -> list[_Record]:
    base = 0x1400 if direction is Direction.RX else 0x1800
    out = []
    for k in range(512):
        comm, mapping = base + k, base + 0x200 + k
        if comm not in eds.od or mapping not in eds.od or isinstance(eds.od[mapping], cod.ODVariable):
            continue
        subs = [s for s in eds.od[mapping].subindices if s > 0]
        n_max = 0  # the entries 1, 2, ... the record has without a gap (a missing one cannot be written)
        while n_max + 1 in subs:
            n_max += 1
        sub0 = eds.var(mapping, 0)
        fixed = sub0 is None or not sub0.writable or any(not eds.writable(mapping, s) for s in subs)
        entries = []
        count = eds.default(mapping, 0) or 0
        for s in range(1, min(int(count), MAX_MAPPED_OBJECTS) + 1):  # (an EDS's 0x80000181 is no count)
            word = eds.default(mapping, s)
            if isinstance(word, int) and word:
                entries.append((word >> 16, (word >> 8) & 0xFF, word & 0xFF))
        cob = eds.default(comm, 1)
        tt = eds.default(comm, 2)
        out.append(_Record(direction, k + 1, n_max, not fixed, eds.writable(comm, 1), eds.writable(comm, 2),
                           int(cob) if isinstance(cob, int) else None, int(tt) if isinstance(tt, int) else None,
                           tuple(entries)))
    return out


# --------------------------------------------------------------------------- planning


@dataclass
class Need:
    """An object a node must carry in a PDO."""

    entry: SignalEntry
    obj: MappedObject
    group: str  # "tx", "rx", "rx_event"


class PdoPacker:
    """Plans the PDOs of the rig's nodes (see the module docstring).

    Parameters
    ----------
    smap : SignalMap
    eds : mapping
        Node name -> :class:`EdsView` of its EDS.
    problem : callable
        ``problem(key, obj, message)``: report a problem.
    notes : list of str
        Where notes for the engineer go.
    master_node_id : int
        The master's node id (its heartbeat COB-ID is reserved).
    """

    def __init__(self, smap: SignalMap, eds: Mapping[str, EdsView], problem: Callable[[str, str | None, str], None],
                 notes: list[str], master_node_id: int) -> None:
        self.smap = smap
        self.eds = eds
        self.problem = problem
        self.notes = notes
        self.master_node_id = master_node_id

    def node_layout(self, node: NodeSpec, needs: list[Need]) -> tuple[PdoLayout, list[tuple[Need, int, int]]]:
        """The node's PDO layout and where each need landed: (need, COB-ID, position in the PDO)."""
        eds = self.eds[node.name]
        recs = {Direction.TX: records(eds, Direction.TX), Direction.RX: records(eds, Direction.RX)}
        pdos: list[tuple[_Record, list[Need], list[MappedObject], int]] = []  # record, needs, entries, type
        for group, direction, ttype in (("tx", Direction.TX, 1), ("rx", Direction.RX, 1),
                                        ("rx_event", Direction.RX, 255)):
            todo = [n for n in needs if n.group == group]
            if not todo:
                continue
            # a PDO the EDS fixes serves the needed objects it carries
            for rec in recs[direction]:
                if rec.mapping_writable or rec.used or not rec.default_entries:
                    continue
                carried = [(i, s) for i, s, _ in rec.default_entries]
                mine = [n for n in todo if (n.obj.index, n.obj.subindex) in carried]
                if not mine:
                    continue
                objs = []
                for i, s, bits in rec.default_entries:
                    hit = next((n for n in mine if (n.obj.index, n.obj.subindex) == (i, s)), None)
                    var = eds.var(i, s)
                    if hit is not None:
                        objs.append(hit.obj)
                    elif var is not None and var.data_type in TYPE_BITS and TYPE_BITS[var.data_type][0] == bits:
                        objs.append(MappedObject(f"(0x{i:04X}:{s:02X})", i, s, var.data_type))
                    else:
                        objs = None
                        break
                if objs is None:
                    continue
                rec.used = True
                todo = [n for n in todo if n not in mine]
                pdos.append((rec, mine, objs, ttype))
                self.notes.append(f"{node.name}: {_PREFIX[direction]}PDO{rec.number} is fixed by {eds.name}; "
                                  f"used as it is")
            # the rest first-fit into records the master may map
            current: tuple[_Record, list[Need], list[MappedObject], int] | None = None
            for n in todo:
                bits = n.obj.bit_length
                if current is not None:
                    rec, mine, objs, _ = current
                    if sum(o.bit_length for o in objs) + bits <= 64 and len(objs) < rec.n_entries:
                        mine.append(n)
                        objs.append(n.obj)
                        continue
                rec = next((r for r in recs[direction] if r.mapping_writable and not r.used and r.n_entries), None)
                if rec is None:
                    have = sum(1 for r in recs[direction] if r.mapping_writable)
                    self.problem(n.entry.key, n.entry.where,
                                 f"no {_PREFIX[direction]}PDO left to carry it: {eds.name} has {have} "
                                 f"{_PREFIX[direction]}PDO(s) the master may map and the map needs more")
                    current = None
                    continue
                rec.used = True
                current = (rec, [n], [n.obj], ttype)
                pdos.append(current)
        specs, placed = [], []
        for rec, mine, objs, ttype in pdos:
            spec = self._spec(node, eds, rec, objs, ttype)
            if spec is None:
                continue
            specs.append(spec)
            for n in mine:
                pos = next(k for k, o in enumerate(objs) if o is n.obj)
                placed.append((n, spec.cob_id, pos))
        disable = []
        for direction in (Direction.TX, Direction.RX):
            for rec in recs[direction]:
                if rec.used or rec.default_cob is None or rec.default_cob & COB_ID_INVALID:
                    continue
                if rec.cob_writable:
                    base = 0x1800 if direction is Direction.TX else 0x1400
                    disable.append((base + rec.number - 1, rec.default_cob | COB_ID_INVALID))
                else:
                    self.notes.append(f"{node.name}: {_PREFIX[direction]}PDO{rec.number} stays enabled (its COB-ID "
                                      f"is fixed by {eds.name}); its frames are ignored")
        return PdoLayout(node.node_id, tuple(sorted(specs, key=lambda p: (p.direction.value, p.number))),
                         tuple(disable)), placed

    def _spec(self, node: NodeSpec, eds: EdsView, rec: _Record, objs: list[MappedObject], ttype: int) -> PdoSpec | None:
        name = f"{_PREFIX[rec.direction]}PDO{rec.number}"
        given = {(n, p): c for n, p, c in self.smap.cob_ids}
        key = "canopen.cob_ids"
        cob = given.get((node.name, name))
        if cob is not None and not rec.cob_writable and rec.default_cob is not None \
                and cob != rec.default_cob & 0x7FF:
            self.problem(key, f"{node.name}.{name}", f"0x{cob:03X} given, but {eds.name} fixes its COB-ID at "
                                                     f"0x{rec.default_cob & 0x7FF:03X}")
            return None
        if cob is None:
            if not rec.cob_writable:
                if rec.default_cob is None or rec.default_cob & COB_ID_INVALID:
                    self.problem(key, f"{node.name}.{name}", f"{eds.name} fixes this PDO's COB-ID and does not "
                                                             f"enable it")
                    return None
                cob = rec.default_cob & 0x7FF
            else:
                cob = predefined_cob_id(rec.direction, rec.number, node.node_id)
                if cob is None:
                    d = rec.default_cob
                    if d is None or d & COB_ID_INVALID or not d & 0x7FF:
                        self.problem(key, f"{node.name}.{name}",
                                     f"PDO {rec.number} has no predefined COB-ID and {eds.name} gives none: "
                                     f"give one, e.g. canopen.cob_ids = {{ \"{node.name}.{name}\" = 0x... }}")
                        return None
                    cob = d & 0x7FF
        if not rec.type_writable and rec.default_type != ttype:
            ok = ttype == 1 and rec.default_type is not None and rec.default_type == 1
            if not ok:
                comm = (0x1400 if rec.direction is Direction.RX else 0x1800) + rec.number - 1
                self.problem(f"{node.key}.eds", f"0x{comm:04X}:02 at {node.name}",
                             f"{name}'s transmission type is fixed at {rec.default_type} by {eds.name}; "
                             f"the check needs {ttype} ({'every SYNC' if ttype == 1 else 'event driven'})")
                return None
        rtr = COB_ID_NO_RTR if (rec.default_cob or 0) & COB_ID_NO_RTR and rec.direction is Direction.TX else 0
        return PdoSpec(name, rec.direction, rec.number, cob, ttype, tuple(objs),
                       write_mapping=rec.mapping_writable, write_cob_id=rec.cob_writable,
                       write_transmission=rec.type_writable, rtr_bit=rtr)

    def check_cob_ids(self, layouts: dict[str, PdoLayout]) -> None:
        """Every COB-ID distinct, valid for a PDO and clear of the rig's other identifiers."""
        reserved: dict[int, str] = {NMT_COB_ID: "NMT", SYNC_COB_ID: "SYNC",
                                    HEARTBEAT_COB_ID_BASE + self.master_node_id: "the master's heartbeat"}
        for n in self.smap.nodes:
            i = n.node_id
            for base, what in ((EMCY_COB_ID_BASE, "EMCY"), (SDO_RX_COB_ID_BASE, "SDO response"),
                               (SDO_TX_COB_ID_BASE, "SDO request"), (HEARTBEAT_COB_ID_BASE, "heartbeat")):
                reserved[base + i] = f"{what} of {n.label}"
        seen: dict[int, str] = {}
        for name, layout in layouts.items():
            for p in layout.pdos:
                who = f"{name}.{p.name}"
                cob = p.cob_id
                if cob in reserved:
                    self.problem("canopen.cob_ids", who, f"COB-ID 0x{cob:03X} is the {reserved[cob]}")
                elif any(lo <= cob <= hi for lo, hi in RESTRICTED_CAN_IDS):
                    self.problem("canopen.cob_ids", who, f"COB-ID 0x{cob:03X} is restricted by CiA 301 "
                                                         f"(no PDO may use it)")
                if cob in seen:
                    self.problem("canopen.cob_ids", who, f"COB-ID 0x{cob:03X} is also {seen[cob]}'s: "
                                                         f"two PDOs overlap")
                seen.setdefault(cob, who)
