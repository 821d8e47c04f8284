"""Version of the isobar Python package (kept equal to the Rust crate's version)."""

__version__ = "0.1.0"
