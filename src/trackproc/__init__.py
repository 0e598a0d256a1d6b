"""trackproc: satellite tracking passes in, orbits with honest error matrices out."""

__version__ = "0.1.0"
