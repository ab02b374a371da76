"""Option helpers shared by the ``lfmdr`` sub-commands' modules (:mod:`lfmdr_gym.cli`,
:mod:`lfmdr_gym.cli_map`): the help formatter, a sub-command's parser, option types and the
option blocks several commands take."""

from __future__ import annotations

import argparse
import textwrap
from collections.abc import Sequence
from typing import Any


class Formatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Shows defaults, except the uninformative None/False (the help text explains those)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.default is None or action.default is False or action.required:
            return action.help
        return super()._get_help_string(action)


def help_text(*paragraphs: str) -> str:
    """Help paragraphs wrapped for the terminal (the raw formatter keeps the blank lines)."""
    return "\n\n".join(textwrap.fill(" ".join(p.split()), width=88) for p in paragraphs)


def add_command(sub: Any, name: str, summary: str, *description: str) -> argparse.ArgumentParser:
    """A sub-command's parser: ``summary`` in ``lfmdr --help``, the ``description`` paragraphs
    in its own help."""
    return sub.add_parser(name, formatter_class=Formatter, help=summary,
                          description=help_text(*description))


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def add_sensor_option(p: argparse.ArgumentParser, what: str, fused: Sequence[str] = ()) -> None:
    """--sensor (also spelled --mode, its older name); ``fused``: fused sets also accepted."""
    from mappers.core.sensors import SENSORS

    p.add_argument("--sensor", "--mode", dest="sensor", required=True,
                   choices=(*SENSORS, *fused), help=what)


def add_method_options(p: argparse.ArgumentParser, default: str) -> None:
    """--method and --param, shared by `run`, `map` and `mrclam`."""
    p.add_argument("--method", default=None,
                   help="a registered method that maps this kind of history, case-insensitive "
                        f"(e.g. CAL-SMA, 'SMA(WGT)', COVIS-AUTO; default: {default}); an older "
                        "label maps with a warning naming its new one, or is refused naming what "
                        "to use (e.g. VIS-BA, covis-power: docs/dead-ends.md)")
    p.add_argument("--param", action="append", default=None, metavar="NAME=VALUE",
                   help="method parameter overriding its default (repeatable), e.g. K=7 or "
                        "n_neighbors=7, sigma2=1, d=4")


def print_warnings(notes: Sequence[str]) -> None:
    """A map's warnings (``Map.warnings``), one line each."""
    for note in notes:
        print(f"warning: {note}")
