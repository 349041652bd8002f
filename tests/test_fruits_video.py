"""The every-fruit video (``bve-mj episode --fruits all --video``): its overlay drawn where the
tracks project, and a short seeded episode recorded to an mp4 that reads back, the episode
the same as without the video."""

from typing import Any

import cv2
import imageio.v2 as imageio
import numpy as np
import pytest

from bve_mj.cli import main
from bve_mj.config import load_settings, with_overrides
from bve_mj.estimation import Belief
from bve_mj.loop.fruit_records import FruitState
from bve_mj.loop.mujoco_fruits import run_every_fruit_episode
from bve_mj.reporting.fruits_video import (
    CONFIRMED,
    LOCALISED,
    TENTATIVE,
    FruitsRecorder,
    Mark,
    draw_marks,
    draw_tracks,
)
from bve_mj.reporting.overlay import _TRUTH, _View
from bve_mj.sim.scene_model import Fruit

W, H, F = 640, 480, 500.0
# a camera at the origin looking along +x (image right = world -y, image up = world +z)
CAM = _View(np.zeros(3), np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]),
            F, ((W - 1) / 2, (H - 1) / 2))  # fmt: skip


def _state(tid: int, centre: list[float], sigma: float, confirmed: bool, localised: bool) -> FruitState:
    belief = Belief(np.r_[centre, 0.03], np.diag([sigma**2] * 3 + [1e-6]))
    return FruitState(tid, belief, confirmed, 3, 0, 3, localised)


def _near(
    img: np.ndarray, u: float, v: float, colour: tuple[int, int, int], tol: int = 40, r: int = 2
) -> bool:
    """Some pixel within ``r`` of (u, v) has this colour (within ``tol`` per channel)."""
    iu, iv = round(u), round(v)
    patch = img[iv - r : iv + r + 1, iu - r : iu + r + 1]
    return bool(np.any(np.all(np.abs(patch.astype(int) - colour) <= tol, axis=-1)))


@pytest.fixture
def written(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Every text cv2.putText draws while the test runs (it still draws it)."""
    texts: list[str] = []
    real = cv2.putText

    def put_text(img: np.ndarray, text: str, *args: Any, **kwargs: Any) -> Any:
        texts.append(text)
        return real(img, text, *args, **kwargs)

    monkeypatch.setattr(cv2, "putText", put_text)
    return texts


def test_tracks_are_drawn_where_they_project(written: list[str]) -> None:
    img = np.zeros((H, W, 3), np.uint8)
    tracks = [
        _state(0, [1.0, 0.0, 0.0], 0.02, True, True),  # centre of the image, 3σ = 30 px
        _state(1, [1.0, 0.3, 0.0], 0.02, False, False),  # 150 px left of it
        _state(2, [1.0, -0.3, 0.1], 0.02, True, False),  # 150 px right, 50 px up
    ]
    truth = [Fruit("a", np.array([1.0, 0.0, -0.3]), 0.03, "red")]  # 150 px below, r = 15 px
    draw_tracks(img, CAM, tracks, truth, order={0: 1, 2: 0}, visiting=2)
    cu, cv = (W - 1) / 2, (H - 1) / 2
    for (du, dv), colour in (((0, 0), LOCALISED), ((-150, 0), TENTATIVE), ((150, -50), CONFIRMED)):
        u, v = cu + du, cv + dv
        assert _near(img, u, v, colour)  # the estimate
        outline = [_near(img, u + eu, v + ev, colour) for eu, ev in ((30, 0), (-30, 0), (0, 30), (0, -30))]
        assert sum(outline) >= 3  # its 3σ outline (its tag may cover one side)
        assert not _near(img, u + 15, v + 15, colour, r=1)  # nothing between centre and outline
    assert _near(img, cu + 15, cv + 150, _TRUTH, tol=100) and _near(img, cu, cv + 135, _TRUTH, tol=100)
    assert not img[int(cv) + 145 : int(cv) + 156, int(cu) - 5 : int(cu) + 6].any()  # an outline
    assert _near(img, cu + 150 + 21, cv - 50, (255, 255, 255), r=3)  # the visited one ringed
    assert {"#0 pick 2", "#1", "#2 pick 1"} <= set(written)


def test_detections_are_circled_and_tagged(written: list[str]) -> None:
    img = np.zeros((H, W, 3), np.uint8)
    marks = [
        Mark((200.0, 300.0), 40.0, "#3", LOCALISED),
        Mark((450.0, 300.0), 10.0, "ignored", (150, 150, 150)),
    ]
    out = draw_marks(img, marks, [("view 2", (255, 255, 255))])
    assert not img.any() and out.shape == img.shape  # a copy
    assert _near(out, 240, 300, LOCALISED) and _near(out, 200, 340, LOCALISED)
    assert _near(out, 460, 300, (150, 150, 150))
    assert {"view 2", "#3", "ignored"} <= set(written)


def test_every_fruit_video_reads_back_and_leaves_the_episode_unchanged(tmp_path, capsys) -> None:
    settings = with_overrides(load_settings("examples/scenarios/suite/ripe_truss.toml"), episode={"views": 3})
    path = tmp_path / "fruits.mp4"
    recorder = FruitsRecorder(path)
    try:
        with_video = run_every_fruit_episode(settings, 4, recorder=recorder)
    finally:
        written = recorder.close()
    reader = imageio.get_reader(str(path))
    frames = [f for f in reader]
    assert written == len(frames) > len(with_video.result.views) * recorder.hold_frames
    assert frames[0].shape == (480, 1280, 3)
    assert frames[-1][:, 640:].std() > 10  # the eye-in-hand image, not the waiting panel

    def strip(doc: Any) -> Any:
        if isinstance(doc, dict):
            skip = ("wall_s", "timings_s", "plan_s", "track_s", "assign_s")
            return {k: strip(v) for k, v in doc.items() if k not in skip}
        return [strip(v) for v in doc] if isinstance(doc, list) else doc

    without = run_every_fruit_episode(settings, 4)
    assert strip(with_video.to_json()) == strip(without.to_json())
    # the command line: the path must end in .mp4; --plots stays the one-target episode's
    config = "examples/scenarios/suite/ripe_truss.toml"
    capsys.readouterr()
    for argv, field in (
        (["--video", str(tmp_path / "x.avi")], "video"),
        (["--plots", str(tmp_path / "p")], "plots"),
    ):
        assert main(["episode", "--fruits", "all", "--config", config, *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and field in err


def test_the_visit_panel_labels_the_fruit_just_picked_and_leaves_out_those_picked_before(
    monkeypatch: pytest.MonkeyPatch, written: list[str]
) -> None:
    from types import SimpleNamespace

    from bve_mj.config import Settings
    from bve_mj.loop.harvest import Visit

    settings = Settings()
    cam = settings.camera
    # the camera at the origin looking along +x (R_world_camera = I: x optical, z up)
    black = np.zeros((cam.height_px, cam.width_px, 3), np.uint8)
    world = SimpleNamespace(
        renderer=SimpleNamespace(render=lambda data, name: black),
        kin=SimpleNamespace(camera_pose=lambda q: (np.zeros(3), np.eye(3))),
        data=None, q=np.zeros(6), settings=settings,
    )  # fmt: skip
    rec = FruitsRecorder("unused.mp4")
    rec._world, rec._writer = world, object()  # type: ignore[assignment]
    monkeypatch.setattr(rec, "_hold", lambda: None)
    rec._tracks = tuple(_state(i, [0.4, y, 0.0], 0.001, True, True) for i, y in ((0, 0.05), (1, -0.05)))
    rec.on_order([0, 1])
    rec.on_visited(Visit(0, 0, True, 0.1, 0.1, 0.05, None, "f0"))  # the first visit takes fruit f0
    assert {"#0 picked", "#1"} <= set(written)
    written.clear()
    rec.on_visited(Visit(1, 1, True, 0.1, 0.1, 0.05, None, None))  # the second takes nothing
    assert "#1" in written and not any(t.startswith("#0") for t in written)
