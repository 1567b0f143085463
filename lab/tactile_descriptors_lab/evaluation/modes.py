"""Names the command line offers, in a module that imports nothing heavy."""

from __future__ import annotations

__all__ = ["SCALINGS"]

#: Feature scalings: none, standardise only, log1p(Activity) + standardise.
SCALINGS: tuple[str, ...] = ("none", "standardize", "log_standardize")
