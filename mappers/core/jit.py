"""Loops compiled with numba on first use, so that importing their module does not import numba.

numba costs about 90 MB of memory and 0.25 s to import, which code that never runs the loops (a
mapper that does not need them, ``lfmdr map FILE`` reading a history) should not pay. A module
writes its loops as plain functions and compiles them when they are first wanted: with
:func:`compiled_on_first_use` as its ``__getattr__`` (PEP 562), or by calling
:func:`compile_in_place` itself. Each is compiled with ``njit(cache=True, nogil=True)`` (cached
on disk, so a process pays the compilation once per installation; callable without the GIL).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

__all__ = ["compile_in_place", "compiled_on_first_use"]


def compile_in_place(namespace: dict, names: Iterable[str], *, prefix: str = "",
                     **options: Any) -> None:
    """Compile, in this order, the plain function ``namespace[prefix + name]`` of each of
    ``names`` and bind it as ``namespace[name]`` (``options``: more of numba's ``njit``
    options, e.g. ``fastmath=True``).

    A compiled function calls another as a global, which numba resolves when it compiles the
    caller: list the callees first."""
    from numba import njit

    jit = njit(cache=True, nogil=True, **options)
    for name in names:
        namespace[name] = jit(namespace[prefix + name])


def compiled_on_first_use(namespace: dict, public: Iterable[str], *, helpers: Iterable[str] = (),
                          **options: Any) -> Callable[[str], Any]:
    """A module ``__getattr__`` (PEP 562) that, at the first access to a name of ``public``,
    compiles the module's ``helpers`` in place and then each plain ``_<name>`` as ``<name>``
    (:func:`compile_in_place`), so that every later access is an ordinary attribute lookup.

    ``namespace`` is the module's ``globals()``; list ``public`` in its ``__all__`` too."""
    public, helpers = tuple(public), tuple(helpers)

    def __getattr__(name: str) -> Any:
        if name not in public:
            raise AttributeError(f"module {namespace['__name__']!r} has no attribute {name!r}")
        compile_in_place(namespace, helpers, **options)
        compile_in_place(namespace, public, prefix="_", **options)
        return namespace[name]

    return __getattr__
