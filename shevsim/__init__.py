"""shevsim - co-simulation of series-hybrid electric vehicles (FMI-style components, fixed-step master)."""
__version__ = "0.1.0"
