"""Errors of the evaluation library (subclasses of the shared typed errors)."""
from __future__ import annotations

from ..errors import InputError


class AssociationError(InputError):
    """No (or too few) pairs of poses could be matched in time between two trajectories."""


class AlignmentError(InputError):
    """Umeyama alignment is impossible (too few or degenerate, e.g. collinear, positions)."""
