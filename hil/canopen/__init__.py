"""The CANopen vocabulary both ends speak: the master in :mod:`hil` and the simulated drives in :mod:`sim`.

Pure and sans-IO (frames and time values in, frames and events out; no bus,
no thread, no clock, no file but the EDS it is asked to parse). It imports
nothing from the rest of emacheck, so a test of this package tests what both
ends rely on (the layering is enforced by ``tests/test_layers.py``).

==================  ==========================================================
module              what
==================  ==========================================================
``frame``           :class:`Frame`, the COB-ID plan, :func:`split_cob_id`
``nmt``             NMT states and commands, NMT and heartbeat frames
``sdo``             SDO client (expedited, segmented), abort codes, abort frames
``pdo``             the drives' PDO layout and codecs, the SDO writes that map it
``units``           scaling between physical values and drive integers
``busload``         bits per frame and the bus load of a SYNC cycle
``emcy``            EMCY codes, the error register, EMCY frames
``cia402``          the CiA 402 state machine as one transition table
``od``              EDS loading and the objects the master requires
``process``         the process image: :class:`DriveMode`, :class:`Setpoint`, :class:`Sample`
``validate``        argument validators (one message style)
``errors``          :class:`CanopenError` and its kin
==================  ==========================================================
"""
