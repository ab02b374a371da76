"""The error a mapping method raises when it cannot embed the data."""

from __future__ import annotations

__all__ = ["MappingError"]


class MappingError(ValueError):
    """A method could not embed the data (eigenproblem failure, solver failure, ...)."""
