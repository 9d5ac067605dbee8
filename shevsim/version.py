"""The package's version (one definition: ``shevsim.__version__``, run metadata and the cache key read it)."""
__version__ = "0.1.0"
