"""emacheck: hardware-in-the-loop maintenance check of dual EMAs (IO shell, CLI, sequence core)."""

__version__ = "0.1.0"
