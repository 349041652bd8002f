"""Every example runs, writes only into its output folder, and leaves the checkout clean."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted(p.name for p in (ROOT / "examples").glob("*.py"))


def _git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout


def _in_git_checkout() -> bool:
    return shutil.which("git") is not None and (ROOT / ".git").exists()


def _args(name: str, out: Path) -> list[str]:
    """Each example's output folder argument (position as its docstring says)."""
    return {
        "approach_video.py": [str(out)],
        "box_detector.py": ["3"],  # prints only
        "gym_policies.py": ["1"],  # episodes per policy (prints only)
        "campaign.py": [str(out / "campaign"), "1"],  # 1 run per cell (5 by default: 39 s)
        "headless_episode.py": ["2"],
        "paper_table.py": ["3"],  # runs per experiment (20 by default: 50 s)
        "pick_figure.py": ["9105", str(out)],
        "plum_figure.py": [str(out)],
        "render_scene.py": ["4", str(out)],
        "rims_figure.py": ["4", str(out)],
        "sample_paths.py": [str(out)],
        "unhide_figure.py": ["3669142227", str(out)],
    }[name]


def test_every_example_is_listed():
    assert EXAMPLES == [
        "approach_video.py",
        "box_detector.py",
        "campaign.py",
        "gym_policies.py",
        "headless_episode.py",
        "paper_table.py",
        "pick_figure.py",
        "plum_figure.py",
        "render_scene.py",
        "rims_figure.py",
        "sample_paths.py",
        "unhide_figure.py",
    ]


@pytest.mark.skipif(not _in_git_checkout(), reason="needs the git checkout")
def test_examples_leave_the_checkout_clean(tmp_path):
    pytest.importorskip("matplotlib")
    before = _git("status", "--porcelain", "--untracked-files=all")
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    for name in EXAMPLES:
        out = tmp_path / name.removesuffix(".py")
        res = subprocess.run(
            [sys.executable, str(ROOT / "examples" / name), *_args(name, out)],
            cwd=ROOT, env=env, capture_output=True, text=True, check=False, timeout=300,
        )  # fmt: skip
        assert res.returncode == 0, f"{name}: {res.stderr[-2000:]}"
        assert "Traceback" not in res.stderr
    assert _git("status", "--porcelain", "--untracked-files=all") == before
    assert (tmp_path / "approach_video" / "approach.mp4").stat().st_size > 0
    assert (tmp_path / "render_scene" / "greenhouse.png").is_file()
    assert (tmp_path / "rims_figure" / "rims.png").is_file()
    assert (tmp_path / "plum_figure" / "plum_chain.png").is_file()
    assert (tmp_path / "sample_paths" / "sample_paths.png").is_file()
    assert (tmp_path / "unhide_figure" / "unhide.png").is_file()
    assert (tmp_path / "campaign" / "campaign" / "summary.json").is_file()
    # the examples' default output folder, out/, is ignored by git wherever it is made
    for path in ("out/x.png", "examples/out/x"):
        assert subprocess.run(["git", "check-ignore", "-q", path], cwd=ROOT, check=False).returncode == 0
