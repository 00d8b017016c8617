"""Layer 0, used by every other layer: argument validation, the entry-point plugin registry and the
type aliases of the public signatures (:mod:`rsocl.common.hints`).

Nothing here imports another part of rsocl.
"""
