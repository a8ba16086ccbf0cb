"""The types of the command line's argument values, and its parser: a value an
option cannot take, or a usage error, is one line naming the option and the value
(exit 2, station.commands.cli), never argparse's usage of a dozen lines. Light: the
command line is parsed before numpy is loaded."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import NoReturn


class ArgumentsRefused(Exception):
    """A bad argument value or a usage error, said in one line (exit 2)."""


class Parser(argparse.ArgumentParser):
    """argparse's parser, whose errors are one line naming the option and the value
    (its own print the whole usage first: a dozen lines for a typo)."""

    def error(self, message: str) -> NoReturn:
        raise ArgumentsRefused(f"{message} ({self.prog} --help lists the options)")


def number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def positive(text: str) -> float:
    """A finite number > 0 (a speed, a length, a time)."""
    value = number(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
    return value


def not_negative(text: str) -> float:
    value = number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}")
    return value


def whole(low: int, high: int | None = None) -> Callable[[str], int]:
    """A whole number within ``low``..``high``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value < low or (high is not None and value > high):
            within = f"from {low} to {high}" if high is not None else f">= {low}"
            raise argparse.ArgumentTypeError(f"expected a whole number {within}, got {text!r}")
        return value
    return parse


def triple(text: str) -> tuple[float, float, float]:
    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y,Z in mm, got {text!r}") from None
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f"expected three values X,Y,Z, got {text!r}")
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected three finite numbers X,Y,Z, got {text!r}")
    return values


def json_table(text: str) -> dict:
    import json

    try:
        value = json.loads(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"expected a JSON object, got {text!r}: {exc}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"expected a JSON object, got {text!r}")
    return value
