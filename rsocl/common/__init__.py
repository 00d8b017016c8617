"""Layer 0, used by every other layer: argument validation and the entry-point plugin registry.

Nothing here imports another part of rsocl.
"""
