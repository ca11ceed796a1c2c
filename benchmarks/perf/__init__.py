"""The performance and accuracy figures behind ``hexapod-bench perf NAME`` (one module per
figure, each with its own ``main(argv)``)."""

from __future__ import annotations

import argparse


def seed(text: str) -> int:
    """An ``argparse`` type for ``--seed``: a non-negative integer (numpy's generators
    refuse a negative one with a traceback)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"a non-negative integer, got {value}")
    return value
