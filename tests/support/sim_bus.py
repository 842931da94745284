"""A minimal master for protocol tests of the simulated nodes: time, frames to the pair (or its fault
injector), SDO transfers by hil.canopen.sdo's client, NMT and SYNC."""

from __future__ import annotations

import struct

from hil.canopen.frame import Frame, sync_frame
from hil.canopen.sdo import SdoClient, SdoEvent

__all__ = ["Bus"]


class Bus:
    """Frames to ``pair`` (anything with ``on_frame(frame, t)``) at the time ``t`` [s] this holds."""

    def __init__(self, pair, sync_period_s: float = 0.002) -> None:
        self.pair = pair
        self.t = 0.0
        self.T = sync_period_s

    def send(self, frame: Frame) -> list[Frame]:
        return self.pair.on_frame(frame, self.t)

    def nmt(self, cs: int, node: int = 0) -> list[Frame]:
        return self.send(Frame(0x000, bytes([cs, node])))

    def sync(self) -> dict[int, Frame]:
        """Advance one SYNC period and send a SYNC; the frames it brings, by COB-ID."""
        self.t += self.T
        return {f.arbitration_id: f for f in self.send(sync_frame())}

    def sdo(self, node: int, index: int, sub: int, data: bytes | None = None) -> bytes:
        """One SDO transfer; returns the uploaded (or written) bytes, raises SdoAbortError."""
        client = SdoClient(node)
        req = client.start_upload(index, sub, self.t) if data is None else \
            client.start_download(index, sub, data, self.t)
        for _ in range(64):
            replies = [f for f in self.send(req) if f.arbitration_id == 0x580 + node]
            if len(replies) != 1:
                raise AssertionError(f"SDO to node {node}: {len(replies)} replies")
            result = client.on_frame(replies[0], self.t)
            if isinstance(result, SdoEvent):
                return result.data
            req = result
        raise AssertionError("SDO transfer did not finish")

    def read(self, node: int, index: int, sub: int, fmt: str) -> int:
        return struct.unpack("<" + fmt, self.sdo(node, index, sub))[0]

    def write(self, node: int, index: int, sub: int, fmt: str, value: int) -> None:
        self.sdo(node, index, sub, struct.pack("<" + fmt, value))
