"""Layer 6, real cameras: the camera-backend contract plugins implement
(:mod:`~rsocl.hardware.backend`), synchronized capture to disk, and calibration of an array.

Imports the layers below it (common, model, files, analysis).
"""
