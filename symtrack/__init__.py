"""symtrack: an agricultural tracked vehicle on soft soil that remembers every pass."""

__version__ = "0.1.0"
