"""Pieces shared by the reading and the writing side: the path type and one-line error text."""

from __future__ import annotations

import os

PathLike = str | os.PathLike[str]


def one_line(error: BaseException) -> str:
    text = str(error) or type(error).__name__
    return " ".join(text.split())
