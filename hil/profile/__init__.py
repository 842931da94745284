"""The profiles: their frozen dataclasses, the TOML loaders, the signal map tables and the rig plan.

==================  ===========================================================================
``config``          the profiles' frozen dataclasses and the hard caps
``load``            TOML -> validated config (every problem named with file and field)
``tables``          the field checks every profile loader uses (keys, scalars, ranges)
``signals``         the actuation profile's signal map tables, and back
``rig``             a profile's rig planned: every node's EDS loaded and checked
==================  ===========================================================================
"""
