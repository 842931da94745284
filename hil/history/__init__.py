"""The wear history: every check's result kept in a database, trends and remaining life per actuator.

``run``, ``analyze`` and ``serv`` record each result (``dry-run`` and
``simulate`` only with ``--history``, marked simulated) into an SQLite file in
the user's data directory or the database ``--history URL`` names (SQLite or
PostgreSQL, SQLAlchemy Core); ``emacheck history`` shows per actuator and
channel the checks, the wear trend and when the backlash reaches B_spec. See
docs/history.md.

Modules:

* :mod:`hil.history.errors`: the typed errors (no database library imported);
* :mod:`hil.history.url`: ``--history`` URLs, the default file (no database library);
* :mod:`hil.history.schema`: the tables (SQLAlchemy Core) and the versioned migrations;
* :mod:`hil.history.store`: :class:`~hil.history.store.HistoryStore`: open, migrate, add, query;
* :mod:`hil.history.record`: a result.json / serv.json -> a record; recording after a check; sync;
* :mod:`hil.history.trends`: series per actuator and channel, steps, fits -> the history document.

Nothing here is imported by ``emacheck run`` before its cyclic loop ends: the
commands import the recording inside the function that runs after the check.
"""
