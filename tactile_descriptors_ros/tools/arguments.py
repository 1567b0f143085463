"""argparse types shared by the ``tactile`` verbs: one home for how a number or a list of numbers is read.

A bad value gets argparse's usage and its one-line error (``tactile demo:
error: argument --speed: must be a finite number above 0, got '0'``, exit 2),
before a verb reads any data.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = ["positive_float", "positive_int", "number_list"]


def positive_float(text: str) -> float:
    """argparse type: a finite number above zero (``--speed``)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (value > 0 and value != float("inf")):
        raise argparse.ArgumentTypeError(f"must be a finite number above 0, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """argparse type: an integer of at least 1 (``--block``)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {text!r}")
    return value


def number_list(what: str, *, integer: bool = False, low: float = 0.0, low_open: bool = True,
                high: float = math.inf, empty: bool = False) -> Callable[[str], list]:
    """argparse type of a comma-separated list of numbers (``--sizes 100,1000``, ``--c-grid 0.25,1``).

    Parameters
    ----------
    what : str
        What one value is, for the message (``"cell counts"``, ``"seconds"``).
    integer : bool
        Whole numbers (``int``) instead of ``float``.
    low, low_open, high : float
        Every value must lie in ``(low, high]`` (``[low, high]`` with
        ``low_open`` False) and be finite.
    empty : bool
        Whether no value at all (``""``) is a list: an option that turns a
        part of the work off that way (``tactile bench --sizes ""``).

    Returns
    -------
    callable
        ``str -> list`` for ``add_argument(type=...)``: the values in the
        order given; empty items (``"1,,2"``, a trailing comma) are skipped;
        no value at all (unless ``empty``), a value that is not a number or
        one out of range raise ``argparse.ArgumentTypeError`` naming the text.
    """
    cast = int if integer else float
    bound = f"{'(' if low_open else '['}{low:g}, {high:g}{']' if math.isfinite(high) else ')'}"

    def parse(text: str) -> list:
        try:
            values = [cast(x) for x in text.split(",") if x.strip()]
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what} joined by ',', got {text!r}") from None
        if not values and not empty:
            raise argparse.ArgumentTypeError(f"expected at least one of the {what}, got {text!r}")
        for v in values:
            if not (math.isfinite(v) and (v > low if low_open else v >= low) and v <= high):
                raise argparse.ArgumentTypeError(f"{what} must lie in {bound}, got {text!r}")
        return values

    return parse
