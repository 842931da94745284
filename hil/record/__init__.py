"""What a check leaves behind: the run record, the run folder, the CAN log, the signals CSV read
back, and the per-cycle timing.

==================  ===========================================================================
``runrecord``       the run record (meta.json) as frozen dataclasses, its JSON both ways
``runfolder``       signals.csv, meta.json, result.json: written once, as it happens; read back
``canlog``          the candump log of every frame, and its decoding into signals
``signals_csv``     a signals CSV read in bounded memory; jumps, constants, short recordings refused
``cycletiming``     per-cycle timing measured in the loop, summarised for the record
==================  ===========================================================================
"""
