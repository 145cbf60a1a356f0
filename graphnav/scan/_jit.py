"""Optional JIT for the scan kernels (:mod:`._icp_fast`, :mod:`._ndt_fast`): numba's ``njit`` when numba
is importable, else the decorated function itself, so the one implementation runs interpreted (slowly,
the same arithmetic) without the optional dependency (``pip install graphnav[fast]``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

try:
    from numba import njit as _njit
except ImportError:  # the kernels run as plain Python
    _njit = None

HAVE_NUMBA = _njit is not None


def njit(*args: Any, **kwargs: Any) -> Any:
    """``numba.njit`` (same arguments) when numba is importable; else the identity decorator."""
    if _njit is not None:
        return _njit(*args, **kwargs)
    if len(args) == 1 and callable(args[0]) and not kwargs:
        return args[0]

    def keep(f: Callable) -> Callable:
        return f

    return keep
