"""A rig writing to the wear history, as its own process (the concurrency and kill tests, the benchmark).

    python tests/support/history_writer.py URL TAG N [BATCH]

opens the history (migrating it if it is new: two writers may race for that), then records ``N``
distinct results (run ids ``TAG-0000``, ...) in transactions of ``BATCH`` results each, printing
``committed K`` after each transaction (flushed), so that a parent that kills it knows what is in.
"""

from __future__ import annotations

import copy
import sys
from pathlib import Path

# tests/ on the path instead of this script's own folder (whose profiles.py would hide the package)
sys.path[0] = str(Path(__file__).resolve().parents[1])

from hil.history.record import record_from_result  # noqa: E402 (after sys.path is set)
from hil.history.store import HistoryStore  # noqa: E402
from support.wear import wear_results  # noqa: E402


def results(tag: str, start: int, n: int) -> list[dict]:
    """``n`` distinct results, run ids ``TAG-<start>`` on."""
    base = wear_results(n=1, seed=0, simulated=False)[0]
    out = []
    for k in range(start, start + n):
        r = copy.deepcopy(base)
        r["trace"]["run_id"] = f"{tag}-{k:04d}"
        r["trace"]["flight_hours"] = float(k)
        out.append(r)
    return out


def main(argv: list[str]) -> int:
    url, tag, n = argv[0], argv[1], int(argv[2])
    batch = int(argv[3]) if len(argv) > 3 else 1
    with HistoryStore.open(url, timeout_s=30.0) as store:
        done = 0
        while done < n:
            recs = [record_from_result(r) for r in results(tag, done, min(batch, n - done))]
            if batch == 1:
                store.add(recs[0])
            else:
                store.add_many(recs)
            done += len(recs)
            print(f"committed {done}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
