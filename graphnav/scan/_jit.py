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


def load_cached(kernel: Any, args: tuple) -> bool:
    """Load the compiled ``kernel`` for ``args`` from numba's cache on disk (``cache=True``) before its first call,
    as that call would (``Dispatcher.compile``: the cache entry of the arguments' types, the machine code linked in,
    registered as an overload) but without the refresh of numba's target context that the dispatcher runs first:
    importing and registering every module of numba's own lowering (~0.1 s CPU of each process that calls a kernel),
    which code compiled earlier does not use -- it is linked against numba's runtime alone, initialised here.
    Returns whether the kernel now has that overload. Anything else (no numba, caching off, no or a stale entry,
    a numba whose internals differ) leaves the kernel to its own first call, which compiles or loads as ever."""
    if _njit is None:
        return False
    try:
        from numba.core.compiler_lock import global_compiler_lock
        from numba.core.runtime import rtsys

        sig = tuple(kernel.typeof_pyval(a) for a in args)
        with global_compiler_lock:
            if sig in kernel.overloads:
                return True
            rtsys.initialize(kernel.targetctx)
            cres = kernel._cache._load_overload(sig, kernel.targetctx)
            if cres is None or cres.objectmode:
                return False
            kernel.targetctx.insert_user_function(cres.entry_point, cres.fndesc, [cres.library])
            kernel.add_overload(cres)
            return True
    except Exception:  # noqa: BLE001 - numba's private API: the kernel's own first call instead
        return False
