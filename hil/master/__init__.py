"""The CANopen master: its sans-IO core, the preflight and the master's-death drill, the events it
reports, and the link that runs it over a transport.

==================  ===========================================================================
``core``            the master core (sans-IO): NMT, SDO client, CiA 402 enabling, the SYNC cycle
``preflight``       the preflight and the master-loss drill (a sans-IO generator)
``limits_setup``    the limits each drive is told to keep itself, and their read-back
``events``          the events the master core reports
``link``            the master core over a transport, as the check loop's link (IO)
==================  ===========================================================================
"""
