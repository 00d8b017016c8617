"""Type aliases of rsocl's public signatures.

They name what the functions accept, for annotations and type checkers; nothing here checks a
value (:mod:`rsocl.common.validation` does).

Examples
--------
>>> from rsocl.common.hints import PerSet
>>> def weight(lam: PerSet) -> float: ...
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Union

from numpy.typing import ArrayLike, DTypeLike

__all__ = ["ArrayLike", "DTypeLike", "PathLike", "PerSet", "Options", "Callback"]

#: A file path: a string or a path object.
PathLike = Union[str, os.PathLike]
#: One number for every set, or a sequence of numbers, one per set of a batch.
PerSet = Union[float, Sequence[float]]
#: Regularizer options by name (values as the options convert them, e.g. from strings).
Options = Mapping[str, Any]
#: ``callback(iteration, residual, theta)`` after each solver iteration; a true result stops the run.
Callback = Callable[[int, Any, Any], Any]
