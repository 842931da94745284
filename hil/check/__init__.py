"""The check: its sequence of steps, the safety supervisor, the freshness limit and the loop.

==================  ===========================================================================
``sequence``        the check sequence core (sans-IO): steps as an Enum, transitions a table
``supervisor``      the safety supervisor core (sans-IO): first violation latched
``staleness``       the sensor-freshness limit, derived from the physics and the drives' own limits
``profileclock``    a motion profile's own time: it waits for periods without a sample (pure)
``runner``          the check loop: sequence + supervisor + run-folder logging over a link (IO)
==================  ===========================================================================
"""
