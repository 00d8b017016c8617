"""Layer 4, looking at results: quality metrics (PSNR, SSIM) and pictures (GIFs, montages).

Imports :mod:`rsocl.common` and :mod:`rsocl.files` (atomic writes).
"""
