"""Layer 3, files: atomic writes, HDF5 captures and reconstructions, TOML rig files.

Imports :mod:`rsocl.common` and :mod:`rsocl.model`.
"""
