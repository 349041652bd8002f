"""The ``bve-mj`` command.

Exit status: 0 on success; 2 on bad input, with one line naming the field and what is
allowed; 1 on an internal failure (or, for a campaign, when a run crashed); 3 when an
episode could not localise the fruit: out of the arm's reach, or never detected.

This module parses and dispatches; each command lives in its own module of this package."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import warnings
from collections.abc import Callable, Iterator, Sequence
from typing import TextIO

from bve_mj.cli.args import EXIT_FAILURE, EXIT_USAGE, UsageError
from bve_mj.cli.campaign import cmd_campaign, cmd_results
from bve_mj.cli.episode import cmd_episode
from bve_mj.cli.paper import cmd_paper
from bve_mj.cli.parser import build_parser
from bve_mj.cli.scene import cmd_draw_scenes, cmd_scene
from bve_mj.cli.suite import cmd_calibrate, cmd_scenarios

__all__ = ["COMMANDS", "main"]

COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "paper": cmd_paper,
    "episode": cmd_episode,
    "campaign": cmd_campaign,
    "recoverability": cmd_campaign,
    "results": cmd_results,
    "scenarios": cmd_scenarios,
    "calibrate": cmd_calibrate,
    "scene": cmd_scene,
    "draw-scenes": cmd_draw_scenes,
}
"""Each command's implementation (the parser, :func:`build_parser`, defines its options)."""


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``bve-mj``; returns the exit status."""
    from bve_mj.errors import BveError, ConfigError

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help()
            return EXIT_USAGE
        from bve_mj.threads import one_blas_thread

        # one BLAS thread: results then match a campaign's (its workers pin it too), and a
        # multi-threaded BLAS only adds overhead to 3x3 algebra
        with one_blas_thread(), _moved_settings_shown():
            command = COMMANDS.get(args.command)
            if command is not None:
                return command(args)
        raise UsageError(f"bve-mj: unknown command {args.command!r}")  # pragma: no cover
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except ConfigError as exc:
        print(f"bve-mj: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except BveError as exc:
        print(f"bve-mj: failed: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print(
            "bve-mj: interrupted (a campaign keeps every finished run: the same command resumes it)",
            file=sys.stderr,
        )
        return 130
    except Exception as exc:  # internal failure: one line, exit 1 (BVE_MJ_DEBUG=1 for the traceback)
        if os.environ.get("BVE_MJ_DEBUG"):
            raise
        print(f"bve-mj: internal error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return EXIT_FAILURE


@contextlib.contextmanager
def _moved_settings_shown() -> Iterator[None]:
    """Within: a setting given under its old name (:class:`bve_mj.errors.SettingMovedWarning`,
    a DeprecationWarning Python would hide) is printed as one line naming the new key."""
    from bve_mj.errors import SettingMovedWarning

    with warnings.catch_warnings():
        warnings.simplefilter("default", SettingMovedWarning)
        shown = warnings.showwarning

        def show(
            message: Warning | str,
            category: type[Warning],
            filename: str,
            lineno: int,
            file: TextIO | None = None,
            line: str | None = None,
        ) -> None:
            if issubclass(category, SettingMovedWarning):
                print(f"bve-mj: warning: {message}", file=sys.stderr)
            else:
                shown(message, category, filename, lineno, file, line)

        warnings.showwarning = show
        yield
