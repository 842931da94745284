"""Self-contained HTML reports: the shell (:mod:`hil.report.shell`) and one module per report.

``maint`` (report.html of a check), ``serv`` (serv_report.html),
``diagnose`` (diagnosis_report.html).
"""
