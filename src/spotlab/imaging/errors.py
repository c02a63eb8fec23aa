"""Errors of the imaging package."""

from __future__ import annotations

from spotlab.core.errors import SpotlabError


class ImagingError(SpotlabError, ValueError):
    """Image input is unusable (wrong shape or type, a bad threshold or gate)."""
