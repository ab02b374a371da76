"""BLAS and OpenMP thread limits for small problems, with one shared controller.

For the small matrices of most maps one BLAS thread is fastest: more threads only compete for a
shared machine's cores. :func:`thread_limit` is threadpoolctl's ``ThreadpoolController.limit``
with the controller built once (scanning the loaded libraries costs 5-10 ms a call).
"""

from __future__ import annotations

from threadpoolctl import ThreadpoolController

__all__ = ["thread_limit"]

_controller: ThreadpoolController | None = None


def thread_limit(limits: int | None):
    """A context holding BLAS and OpenMP to ``limits`` threads (None: the libraries decide)."""
    global _controller
    if _controller is None:
        _controller = ThreadpoolController()
    return _controller.limit(limits=limits)
