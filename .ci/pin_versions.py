"""Print the installed versions of bve_mj's dependencies (its extras' too), as pip constraints.

    python3 .ci/pin_versions.py > .ci/constraints.txt

Run it after an upgrade that CI passes: ``.ci/run`` installs under the file it writes, so the
suite's figures repeat from session to session (episodes' trajectories move with mujoco,
numpy, opencv and scipy). Walks the installed distributions' requirements from ``bve_mj``
with the extras named (default: all of pyproject.toml's); bad input is one line, exit 2.
"""

from __future__ import annotations

import argparse
import importlib.metadata as md
import re
import sys

from packaging.requirements import Requirement

HEADER = """\
# The versions CI last passed on (Python {py}, Linux x86-64): .ci/run installs under them, so
# episodes and suite figures are the same from session to session. Trajectories move with
# mujoco, numpy, opencv and scipy versions. Regenerate after an upgrade that CI passes:
# python3 .ci/pin_versions.py > .ci/constraints.txt (README, "Pinned versions")."""


def _key(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def pinned(extras: tuple[str, ...]) -> dict[str, str]:
    """{normalised name: installed version} of everything bve_mj with ``extras`` needs."""
    found: dict[str, str] = {}

    def walk(name: str, wanted: tuple[str, ...]) -> None:
        try:
            dist = md.distribution(name)
        except md.PackageNotFoundError:
            return  # a requirement of another platform or Python (a marker pip skipped)
        if _key(name) in found and not wanted:
            return
        found[_key(name)] = dist.version
        for text in dist.requires or []:
            req = Requirement(text)
            if req.marker is None or any(req.marker.evaluate({"extra": e}) for e in ("", *wanted)):
                walk(req.name, tuple(req.extras))

    walk("bve_mj", extras)
    found.pop("bve-mj", None)
    return found


def main(argv: list[str] | None = None) -> int:
    try:
        offered = tuple(md.metadata("bve_mj").get_all("Provides-Extra") or ())
    except md.PackageNotFoundError:
        print("pin_versions.py: error: bve_mj is not installed (pip install -e .)", file=sys.stderr)
        return 2
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--extras", default=",".join(offered), help="comma-separated extras to pin")
    args = parser.parse_args(argv)
    extras = tuple(e.strip() for e in args.extras.split(",") if e.strip())
    unknown = [e for e in extras if e not in offered]
    if unknown:
        print(
            f"pin_versions.py: error: --extras {','.join(unknown)}; allowed: {','.join(offered)}",
            file=sys.stderr,
        )
        return 2
    print(HEADER.format(py=".".join(map(str, sys.version_info[:2]))))
    for name, version in sorted(pinned(extras).items()):
        print(f"{name}=={version}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
