"""From a recording to a result: the orchestration over the pure analysis of :mod:`blf`.

``maint`` (the maintenance check: segments, LVDT calibration, BLFmaint,
result.json), ``serv`` (BLFserv: calibration choice, serv.json) and
``diagnose`` (a recording as a replay model, diagnosis.json). No terminal
output here; the commands of :mod:`hil.cli` print and write the reports.
"""
