"""Scene configurations drawn at random (``bve-mj draw-scenes``): valid, reproducible, spread
over the scene space, never overwriting; calibrated over and run like any scenario file."""

import collections
import json

import numpy as np
import pytest

from bve_mj.campaigns.drawn_scenes import draw_scene, scene_toml, write_drawn_scenes
from bve_mj.campaigns.scenarios import load_suite
from bve_mj.cli import main
from bve_mj.config import settings_from_dict
from bve_mj.config.scene import FRUIT_TYPE_PER_TRUSS
from bve_mj.errors import ConfigError
from bve_mj.estimation.noise import load_noise_model


def test_every_draw_is_a_valid_scenario_and_the_space_is_spread():
    rng = np.random.default_rng(0)
    seen = collections.Counter()
    for _ in range(400):
        description, sections = draw_scene(rng)
        settings = settings_from_dict(sections)
        assert scene_toml(description, sections).startswith(f"# {description}\n[scene]\n")
        sc = settings.scene
        lo, hi = FRUIT_TYPE_PER_TRUSS[sc.fruit_type]
        assert lo <= sc.fruit_per_truss <= hi and 0 <= sc.target_index < sc.fruit_per_truss
        if sc.ripeness:
            assert sc.ripeness[sc.target_index] == "red"
        seen.update([sc.fruit_type, sc.truss_layout])
        seen["headlight"] += sc.headlight
        seen["sensor"] += "sensor" in sections
        seen["given ripeness"] += bool(sc.ripeness)
    for name in (*FRUIT_TYPE_PER_TRUSS, "chain", "cluster"):
        assert seen[name] >= 40, (name, seen[name])
    assert 50 <= seen["headlight"] <= 110  # 20% of 400
    assert 80 <= seen["sensor"] <= 160  # 30%
    assert 160 <= seen["given ripeness"] <= 240  # half


def test_the_same_seed_writes_the_same_files_and_another_seed_others(tmp_path):
    a = write_drawn_scenes(tmp_path / "a", 12, 7)
    b = write_drawn_scenes(tmp_path / "b", 12, 7)
    c = write_drawn_scenes(tmp_path / "c", 12, 8)
    assert [p.name for p in a] == [p.name for p in b] and len(a) == 12
    assert [p.read_bytes() for p in a] == [p.read_bytes() for p in b]
    assert [p.read_bytes() for p in a] != [p.read_bytes() for p in c]
    suite = load_suite(tmp_path / "a")  # each loads as a scenario, its comment its description
    assert len(suite) == 12 and all(sc.description.startswith("Drawn scene") for sc in suite)


def test_nothing_is_overwritten_and_nothing_written_when_refused(tmp_path):
    folder = tmp_path / "d"
    folder.mkdir()
    (folder / "drawn_3_1.toml").write_text("mine")
    with pytest.raises(ConfigError, match="nothing is overwritten"):
        write_drawn_scenes(folder, 4, 3)
    assert sorted(p.name for p in folder.iterdir()) == ["drawn_3_1.toml"]
    assert (folder / "drawn_3_1.toml").read_text() == "mine"
    (tmp_path / "file").write_text("")
    with pytest.raises(ConfigError, match="can write"):
        write_drawn_scenes(tmp_path / "file" / "under", 2, 3)  # a file in the way: not a folder
    with pytest.raises(ConfigError, match="count"):
        write_drawn_scenes(folder, 0, 3)
    with pytest.raises(ConfigError, match="seed"):
        write_drawn_scenes(folder, 2, -1)


@pytest.mark.parametrize(
    ("argv", "field"),
    [
        (["draw-scenes", "--count", "0", "--out", "x"], "count"),
        (["draw-scenes", "--count", "many", "--out", "x"], "count"),
        (["draw-scenes", "--seed", "-3", "--out", "x"], "seed"),
        (["calibrate", "--drawn", "-1"], "drawn"),
    ],
)
def test_bad_input_exits_2_with_one_line(argv, field, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err and "Traceback" not in err
    assert not any(tmp_path.iterdir())


def test_draw_scenes_writes_files_that_scenarios_runs(tmp_path, capsys):
    out = tmp_path / "drawn"
    assert main(["draw-scenes", "--count", "3", "--seed", "11", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "drawn_11_0.toml" in printed and "bve-mj scenarios --dir" in printed
    assert main(["draw-scenes", "--count", "3", "--seed", "11", "--out", str(out)]) == 2  # not again
    assert len(list(out.glob("*.toml"))) == 3


def test_calibrate_adds_one_scene_of_each_drawn_configuration(tmp_path, capsys):
    out, rows = tmp_path / "model.json", tmp_path / "rows.json"
    argv = ["calibrate", "--only", "clean", "--scenes", "1", "--views", "9", "--drawn", "2", "--seed", "5"]
    assert main([*argv, "--workers", "1", "--out", str(out), "--json", str(rows), "--quiet"]) == 0
    doc = json.loads(rows.read_text())
    by_scenario = collections.Counter(r["scenario"] for r in doc["rows"])
    assert by_scenario == {"clean": 9, "drawn_5_0": 9, "drawn_5_1": 9}
    assert "2 drawn scenes" in load_noise_model(str(out)).source


def test_episodes_in_drawn_configurations_end_with_an_outcome_and_claim_only_what_holds(tmp_path):
    """Four configurations nobody chose (draw seed 2026), one closed-loop episode each: each
    ends with an outcome, and one that claims the fruit localised is within 5 mm and holds
    the truth inside its 99.9% ellipsoid."""
    from bve_mj.config import with_overrides
    from bve_mj.loop.mujoco import run_mujoco_episode
    from bve_mj.loop.outcomes import Outcome

    write_drawn_scenes(tmp_path, 4, 2026)
    for sc in load_suite(tmp_path):
        settings = with_overrides(sc.settings(), episode={"views": 8})
        ep = run_mujoco_episode(settings, 1)
        assert isinstance(ep.result.outcome, Outcome), sc.name
        if ep.result.outcome in ("converged", "stable"):
            assert ep.final_error_mm < 5.0, (sc.name, ep.final_error_mm)
            assert ep.result.final.mahalanobis_sq(ep.truth) < 16.27, sc.name
