"""Real-time set-up of a cyclic process (``emacheck run`` and ``emacheck sim-serve``), best effort.

Locked memory (no page fault inside a SYNC cycle), the garbage collector
frozen or off, SCHED_FIFO on request; each function says what it managed.
"""

from __future__ import annotations

import gc
import os


def lock_memory() -> str:
    """Lock the process's pages in RAM (``mlockall(MCL_CURRENT | MCL_FUTURE)``), best effort.

    A page fault in the middle of a SYNC cycle costs time the drives do not
    have (in user-mode-linux about 0.1 ms each); locked pages are faulted in
    once, here. Returns "locked" or why not.
    """
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        if libc.mlockall(1 | 2) != 0:
            return f"not locked ({os.strerror(ctypes.get_errno())})"
    except (OSError, AttributeError) as exc:
        return f"not locked ({exc})"
    return "locked"


def realtime_priority(priority: int = 50) -> str:
    """Run this process under SCHED_FIFO ``priority``, best effort.

    Real drives answer a SYNC within microseconds whatever the master does;
    the simulated ones must not wait for the master's time slice on a shared
    CPU. Returns "SCHED_FIFO N" or why not.
    """
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return f"normal scheduling ({exc})"
    return f"SCHED_FIFO {priority}"


def end_realtime() -> None:
    """After a bounded cyclic loop (:func:`prepare_realtime` with ``bounded=True``): the garbage
    collector back on, SCHED_OTHER (analysis and plotting must not run real-time)."""
    gc.enable()
    try:
        if os.sched_getscheduler(0) != os.SCHED_OTHER:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (OSError, AttributeError):
        pass


def prepare_realtime(priority: int, *, bounded: bool = False) -> str:
    """Set this process up for a cyclic loop: memory locked, GC frozen, SCHED_FIFO ``priority`` if > 0.

    ``gc.freeze`` moves every object made so far (profiles, object dictionaries,
    imported modules) out of the collector's reach, so no collection inside a
    SYNC cycle scans them. ``bounded`` (a loop that ends, like the check of
    ``emacheck run``): the cyclic collector is switched off until
    :func:`end_realtime` (reference counting still frees the loop's objects;
    no collection pause can fall into a SYNC cycle). Returns what was done,
    for the terminal.
    """
    memory = lock_memory()
    sched = realtime_priority(priority) if priority > 0 else "normal scheduling"
    gc.collect()
    gc.freeze()
    if bounded:
        gc.disable()
    return f"memory {memory}, {sched}" + (", garbage collector off" if bounded else "")
