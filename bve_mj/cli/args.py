"""What the commands share: exit statuses, one-line usage errors, argument checks, progress."""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn, get_args

__all__ = [
    "EXIT_FAILURE",
    "EXIT_NOT_LOCALISED",
    "EXIT_OK",
    "EXIT_USAGE",
    "INT_MAXIMA",
    "MAX_RUNS",
    "Parser",
    "UsageError",
    "check_output_path",
    "float_arg",
    "given",
    "grid_text",
    "int_arg",
    "one_of",
    "progress_printer",
    "version_text",
]

if TYPE_CHECKING:
    pass


EXIT_OK = 0


EXIT_FAILURE = 1


EXIT_USAGE = 2


EXIT_NOT_LOCALISED = 3


class UsageError(Exception):
    pass


class Parser(argparse.ArgumentParser):
    """argparse that reports bad input in one line and exits 2."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{self.prog}: {message}")


def one_of(literal: Any, sep: str = ", ", last: str = " or ") -> str:
    """The allowed values of a choice (a Literal of :mod:`bve_mj.config.fields`, where each is
    defined once) for a help text, ``auto`` left out: "bve, random or circle"."""
    names = [str(v) for v in get_args(literal) if v != "auto"]
    return names[0] if len(names) == 1 else sep.join(names[:-1]) + last + names[-1]


def version_text() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("bve_mj")
    except PackageNotFoundError:  # pragma: no cover (run from a source tree, not installed)
        return "unknown (not installed)"


INT_MAXIMA = {
    "seed": 2**63 - 1,
    "workers": 1024,
    "views": 10_000,
    "steps": 10_000,
    "count": 10_000,
    "drawn": 10_000,
    "pick": 10,
}
"""The largest value of each integer option; every other count (runs, seeds, scenes) at most
``MAX_RUNS``: a mistyped ``--runs 1000000000000`` is an error, not a run that never ends."""
MAX_RUNS = 100_000


def int_arg(name: str, text: str | None, minimum: int, maximum: int | None = None) -> int | None:
    """The integer option ``name`` (None when not given), within [minimum, maximum] (default
    its maximum in :data:`INT_MAXIMA`)."""
    from bve_mj.errors import ConfigError

    if text is None:
        return None
    maximum = INT_MAXIMA.get(name, MAX_RUNS) if maximum is None else maximum
    allowed = f"an integer in [{minimum}, {maximum}]"
    try:
        value = int(text)
    except ValueError:
        raise ConfigError(name, text, allowed) from None
    if not minimum <= value <= maximum:
        raise ConfigError(name, text, allowed)
    return value


def check_output_path(name: str, path: str | None) -> Path | None:
    from bve_mj.errors import ConfigError

    if path is None:
        return None
    p = Path(path)
    if p.is_dir():
        raise ConfigError(name, path, "a file path, not a directory")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise ConfigError(name, path, f"a path in an existing directory ({parent} does not exist)")
    if not os.access(parent, os.W_OK):
        raise ConfigError(name, path, f"a path in a writable directory ({parent} is not writable)")
    return p


def progress_printer(enabled: bool) -> Callable[[int, int], None]:
    """A progress callback ``report(done, total)`` drawing a tqdm bar on stderr (runs done,
    rate, time left); nothing when ``enabled`` is false. A new total starts a new bar."""
    bar: Any = None

    def report(done: int, total: int) -> None:
        nonlocal bar
        if not enabled:
            return
        if bar is None or bar.total != total:
            from tqdm import tqdm

            if bar is not None:
                bar.close()
            bar = tqdm(total=total, unit="run", file=sys.stderr, dynamic_ncols=True, leave=True)
        bar.update(max(0, done - bar.n))
        if done >= total:
            bar.close()
            bar = None

    return report


def given(**values: object) -> dict[str, object]:
    """The options the user gave (not None): only these override the settings file."""
    return {k: v for k, v in values.items() if v is not None}


def float_arg(
    name: str, text: str | None, minimum: float, strict: bool = False, maximum: float = math.inf
) -> float | None:
    """The number option ``name`` (None when not given): finite, at least ``minimum`` (above
    it when ``strict``) and at most ``maximum``."""
    from bve_mj.errors import ConfigError

    if text is None:
        return None
    top = "" if math.isinf(maximum) else f" and <= {maximum:g}"
    allowed = f"a number {'>' if strict else '>='} {minimum:g}{top}"
    try:
        value = float(text)
    except ValueError:
        raise ConfigError(name, text, allowed) from None
    if not math.isfinite(value) or not minimum <= value <= maximum or (strict and value == minimum):
        raise ConfigError(name, text, allowed)
    return value


def grid_text(errors: Sequence[float]) -> str:
    if not errors:
        return "default"
    if len(errors) > 3:
        return f"{errors[0]:g}..{errors[-1]:g} m ({len(errors)} values)"
    return ",".join(f"{e:g}" for e in errors) + " m"
