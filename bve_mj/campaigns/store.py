"""The run store: one SQLite row per finished run, committed as each comes back, with the
settings, seed and code that started the campaign."""

from __future__ import annotations

import json
import sqlite3
import subprocess
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from bve_mj.errors import ConfigError

__all__ = ["STORE_FORMAT", "RunStore", "code_identity"]

STORE_FORMAT = 1


# --------------------------------------------------------------------------- store
def _first_difference(a: Any, b: Any, path: str = "") -> str | None:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            d = _first_difference(a.get(k), b.get(k), f"{path}.{k}" if path else k)
            if d:
                return d
        return None
    return None if a == b else f"{path or 'value'}: {a!r} here, {b!r} asked"


def code_identity() -> dict[str, str]:
    """The code that makes a run: the package version and, from a git checkout, its commit
    (``+dirty`` with uncommitted changes to tracked files; ``unknown`` outside a checkout)."""
    from bve_mj import __version__

    here = Path(__file__).resolve().parent
    commit = "unknown"
    try:
        head = subprocess.run(
            ["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10
        )
        if head.returncode == 0:
            commit = head.stdout.strip()
            dirty = subprocess.run(
                ["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
                capture_output=True, text=True, timeout=10,
            )  # fmt: skip
            if dirty.returncode == 0 and dirty.stdout.strip():
                commit += "+dirty"
    except (OSError, subprocess.SubprocessError):
        pass
    return {"version": __version__, "commit": commit}


class RunStore:
    """The campaign's SQLite database: finished runs by key, the identity they share, and the
    code that made them (:func:`code_identity`).

    A campaign resumed under other code than the one that started it mixes rows of two
    programs: :attr:`code_change` says so (the CLI prints it); ``strict`` refuses instead."""

    FILENAME = "runs.sqlite"

    def __init__(
        self,
        directory: str | Path,
        identity: dict[str, Any],
        code: dict[str, str] | None = None,
        strict: bool = False,
    ) -> None:
        self.path = Path(directory) / self.FILENAME
        self.code_change: str | None = None
        ident = json.loads(json.dumps(identity))
        try:
            self._db = sqlite3.connect(self.path, timeout=30.0)
            self._db.execute("CREATE TABLE IF NOT EXISTS meta (name TEXT PRIMARY KEY, value TEXT NOT NULL)")
            self._db.execute(
                "CREATE TABLE IF NOT EXISTS runs "
                "(key TEXT PRIMARY KEY, outcome TEXT NOT NULL, row TEXT NOT NULL)"
            )
            found = self._db.execute("SELECT value FROM meta WHERE name = 'identity'").fetchone()
            if found is None:
                with self._db:
                    self._db.execute("INSERT INTO meta VALUES ('identity', ?)", (json.dumps(ident),))
            else:
                diff = _first_difference(json.loads(found[0]), ident)
                if diff is not None:
                    self._db.close()
                    raise ConfigError(
                        "out",
                        str(directory),
                        "a new directory, or the settings and seed of the campaign already in it "
                        f"(they differ at {diff})",
                    )
            if code is not None:
                self._check_code(str(directory), code, strict)
        except sqlite3.DatabaseError as exc:
            raise ConfigError(
                "out", str(directory), f"a campaign directory ({self.path.name} is unreadable: {exc})"
            ) from None

    def _check_code(self, directory: str, code: dict[str, str], strict: bool) -> None:
        found = self._db.execute("SELECT value FROM meta WHERE name = 'code'").fetchone()
        if found is None:
            with self._db:
                self._db.execute("INSERT INTO meta VALUES ('code', ?)", (json.dumps(code),))
            return
        made = json.loads(found[0])
        if made == code:
            return
        change = (
            f"its runs were made by bve_mj {made.get('version')} at commit {made.get('commit')}; "
            f"this is {code['version']} at {code['commit']}"
        )
        if strict:
            self._db.close()
            raise ConfigError("out", directory, f"a campaign made by this code (--strict: {change})")
        self.code_change = change

    def done(self) -> set[str]:
        """Keys of the finished runs (a crashed run is not finished: it is run again)."""
        return {k for (k,) in self._db.execute("SELECT key FROM runs WHERE outcome != 'crashed'")}

    def add(self, rows: Iterable[dict[str, Any]]) -> None:
        """Store rows in one transaction (all or none)."""
        with self._db:
            self._db.executemany(
                "INSERT OR REPLACE INTO runs VALUES (?, ?, ?)",
                [(r["key"], r["outcome"], json.dumps(r)) for r in rows],
            )

    def rows(self, keys: Iterable[str]) -> list[dict[str, Any]]:
        """The stored rows of ``keys`` that are done, in the order given."""
        wanted = list(keys)
        found = {k: json.loads(r) for k, r in self._db.execute("SELECT key, row FROM runs")}
        return [found[k] for k in wanted if k in found]

    def close(self) -> None:
        self._db.close()
