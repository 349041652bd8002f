"""What the example and benchmark scripts share with the command line: bad input is one line on
stderr naming the argument and what is allowed, and exit status 2 (never a traceback).

    ap = ScriptParser(description=__doc__)
    ap.add_argument("--episodes", type=integer(1), default=10)
    ap.add_argument("--seed", type=SEED, default=0)
    args = ap.parse_args()
    guarded(lambda: main(args))  # a ConfigError the run raises (a scenario name, a file) too
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import NoReturn, TypeVar

from bve_mj.cli.args import EXIT_USAGE, MAX_RUNS, float_arg, int_arg

__all__ = ["SEED", "ScriptParser", "folder", "guarded", "integer", "integers", "names", "number"]

T = TypeVar("T")


class ScriptParser(argparse.ArgumentParser):
    """argparse that reports bad input in one line (no usage block) and exits 2."""

    def error(self, message: str) -> NoReturn:
        print(f"{self.prog}: error: {message}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE)


def integer(minimum: int, maximum: int = MAX_RUNS) -> Callable[[str], int]:
    """An argparse ``type``: an integer in [minimum, maximum] (a mistyped count is an error,
    not a run that never ends)."""

    def parse(text: str) -> int:
        from bve_mj.errors import ConfigError

        try:
            value = int_arg("", text, minimum, maximum)
        except ConfigError as exc:
            raise argparse.ArgumentTypeError(f"got {text!r}; allowed: {exc.allowed}") from None
        assert value is not None
        return value

    return parse


SEED = integer(0, 2**63 - 1)
"""An argparse ``type`` for a seed: an integer in [0, 2⁶³ - 1]."""


def number(minimum: float, maximum: float = math.inf) -> Callable[[str], float]:
    """An argparse ``type``: a finite number in [minimum, maximum]."""

    def parse(text: str) -> float:
        from bve_mj.errors import ConfigError

        try:
            value = float_arg("", text, minimum, maximum=maximum)
        except ConfigError as exc:
            raise argparse.ArgumentTypeError(f"got {text!r}; allowed: {exc.allowed}") from None
        assert value is not None
        return value

    return parse


def names(allowed: Iterable[str]) -> Callable[[str], list[str]]:
    """An argparse ``type``: comma-separated names, each one of ``allowed``, at least one."""
    known = list(allowed)

    def parse(text: str) -> list[str]:
        given = [n.strip() for n in text.split(",") if n.strip()]
        if not given or any(n not in known for n in given):
            allowed = "comma-separated names from " + ", ".join(known)
            raise argparse.ArgumentTypeError(f"got {text!r}; allowed: {allowed}")
        return given

    return parse


def integers(minimum: int, maximum: int) -> Callable[[str], list[int]]:
    """An argparse ``type``: comma-separated integers, each in [minimum, maximum], at least one."""
    one = integer(minimum, maximum)

    def parse(text: str) -> list[int]:
        try:
            values = [one(t) for t in text.split(",")]
        except argparse.ArgumentTypeError:
            values = []
        if not values:
            raise argparse.ArgumentTypeError(
                f"got {text!r}; allowed: comma-separated integers in [{minimum}, {maximum}]"
            )
        return values

    return parse


def folder(text: str) -> str:
    """An argparse ``type``: an output folder, there or made by the script with its parents:
    not a file, nor inside one."""
    path = Path(text)
    existing = next((p for p in (path, *path.parents) if p.exists()), Path("."))
    if not existing.is_dir():
        what = "a folder, not a file" if existing == path else f"a folder, not inside the file {existing}"
        raise argparse.ArgumentTypeError(f"got {text!r}; allowed: {what}")
    return text


def guarded(run: Callable[[], T]) -> T:
    """``run()``, with a :class:`~bve_mj.errors.ConfigError` it raises (bad input found while
    running: a scenario name, a settings file) reported as one line on stderr, exit 2."""
    from bve_mj.errors import ConfigError

    try:
        return run()
    except ConfigError as exc:
        prog = sys.argv[0].rsplit("/", 1)[-1] if sys.argv and sys.argv[0] else "script"
        print(f"{prog}: error: {exc}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None
