"""The wear history: every check's result kept in a database, trends and remaining life per actuator.

``run``, ``analyze`` and ``serv`` record each result (``dry-run`` and
``simulate`` only with ``--history``, marked simulated) into an SQLite file in
the user's data directory or the database ``--history URL`` names (SQLite or
PostgreSQL, SQLAlchemy Core); ``emacheck history`` shows per actuator and
channel the checks, the wear trend and when the backlash reaches B_spec. See
docs/history.md.

Modules:

* the typed errors: :class:`hil.errors.HistoryError` and its two kinds (no database library imported);
* :mod:`hil.profile.history_url`: ``--history`` URLs (the profile's ``history.url``), the default file (no
  database library);
* :mod:`hil.history.schema`: the tables (SQLAlchemy Core) and the versioned migrations;
* :mod:`hil.history.store`: :class:`~hil.history.store.HistoryStore`: open, migrate, add, query;
* :mod:`hil.history.record`: a result.json / serv.json -> a record (:class:`~hil.history.record.CheckRecord`);
* :mod:`hil.history.sync`: records into a store: after a check (never raises), ``emacheck history sync``;
* :mod:`hil.history.trends`: series per actuator and channel, steps, fits -> the history document.

Nothing here is imported by ``emacheck run`` before its cyclic loop ends: the
commands import the recording inside the function that runs after the check.
"""
