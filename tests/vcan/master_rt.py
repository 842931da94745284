"""Start `emacheck ...` (here: `run`) as a real-time master: memory locked, SCHED_FIFO.

``python tests/vcan/master_rt.py run --interface socketcan ...`` is
``emacheck run ...`` after ``mlockall(MCL_CURRENT | MCL_FUTURE)``,
``gc.freeze()`` and SCHED_FIFO priority 40 (below sim-serve's 50): in
user-mode-linux a page fault costs ~0.1 ms, and the master's first cycles
(new code paths, growing heap) otherwise fall so far behind the SYNC that its
socket's receive queue overflows and a heartbeat is lost; and at normal
priority candump's time slices delay the master's cycle by ~10 ms now and
then, enough for a stale position setpoint to trip max_velocity_mm_per_s.
The code path is hil.cli.main's, unchanged. (Until ``emacheck run`` does
this itself, see hil.serve.lock_memory and hil.serve.realtime_priority.)
"""

from __future__ import annotations

import gc
import sys
from pathlib import Path

# the checkout under test, not whatever emacheck is installed (sys.path[0] is tests/vcan here)
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import hil.canopen_link  # noqa: F401  (the run's modules are loaded before locking)
import hil.commands  # noqa: F401
import hil.report  # noqa: F401
import hil.runner  # noqa: F401
from hil.cli import main
from hil.serve import lock_memory, realtime_priority

if __name__ == "__main__":
    state = lock_memory()
    gc.collect()
    gc.freeze()
    print(f"master memory {state}, {realtime_priority(40)}", flush=True)
    sys.exit(main(sys.argv[1:]))
