"""Granular resistive force laws as pure numpy functions in SI units, one module per law."""
