"""Pool workers end with the run that started them (bve_mj.campaigns.executors)."""

import subprocess
import sys
import time
from pathlib import Path

import pytest

_PARENT = """
import time
from bve_mj.campaigns.executors import local_batches
for _ in local_batches(time.sleep, [120.0, 120.0], 2):
    pass
"""


def _children(pid: int) -> list[int]:
    out = []
    for status in Path("/proc").glob("[0-9]*/status"):
        try:
            fields = dict(line.split(":\t", 1) for line in status.read_text().splitlines() if ":\t" in line)
        except OSError:
            continue
        if fields.get("PPid", "").strip() == str(pid):
            out.append(int(status.parent.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "State:\tZ" not in state


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")
def test_a_run_killed_outright_leaves_no_worker_behind():
    """A run whose two workers sleep 120 s each is killed with SIGKILL (no ``finally`` runs):
    both workers are gone within 10 s, not 120."""
    parent = subprocess.Popen([sys.executable, "-c", _PARENT])
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and len(workers) < 2:
            time.sleep(0.2)
            workers = [p for p in _children(parent.pid) if _alive(p)]
        assert len(workers) >= 2, "the pool's workers never started"
        time.sleep(1.0)  # each worker past its initializer, asleep in its task
        parent.kill()
        parent.wait(10.0)
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and any(_alive(p) for p in workers):
            time.sleep(0.2)
        assert not any(_alive(p) for p in workers)
    finally:  # nothing left behind, whatever failed (a worker killed twice is no harm)
        parent.kill()
        for p in {*workers, *_children(parent.pid)}:
            subprocess.run(["kill", "-9", str(p)], check=False, capture_output=True)
