"""The MJCF files people open: the committed arm and scene files are what the generator writes
from the runtime's model (and compile to it exactly), every shipped XML compiles and steps 1 s
with zero warnings, the models ship in the wheel, and ``bve-mj scene`` writes the episode's
greenhouse as a folder MuJoCo loads on its own."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bve_mj.cli import main
from bve_mj.config import Settings, load_settings
from bve_mj.loop.mujoco import episode_settings
from bve_mj.loop.start import start_episode
from bve_mj.robot import arm_kinematics
from bve_mj.robot.description import models_dir
from bve_mj.sim.arm import compile_arm
from bve_mj.sim.mjcf import ARM_FILE, MANIFEST, SCENE_FILE, write_model_files

REPO = Path(__file__).resolve().parents[1]
ARM_DIR = models_dir() / "manipulator_h"
SHIPPED = sorted(models_dir().rglob("*.xml"))
REGENERATE = "python -m bve_mj.sim.mjcf"


# --------------------------------------------------------------------------- the committed files
def _differences(a: ET.Element, b: ET.Element, where: str = "") -> list[str]:
    """Where two XML trees differ: tags, attribute names, text, and values (numbers to 1e-12
    relative, so a last-digit difference of another platform's libm is not drift)."""
    here = f"{where}/{a.tag if isinstance(a.tag, str) else 'comment'}"
    if a.tag != b.tag or (a.text or "").strip() != (b.text or "").strip():
        return [f"{here}: {a.tag} {a.text!r} != {b.tag} {b.text!r}"]
    keys = set(a.attrib) & set(b.attrib)
    out = [f"{here}: attributes {sorted(a.attrib)} != {sorted(b.attrib)}"] if set(a.attrib) != keys else []
    out += [f"{here}: attributes {sorted(a.attrib)} != {sorted(b.attrib)}"] if set(b.attrib) != keys else []
    for k in sorted(keys):
        x, y = a.get(k, ""), b.get(k, "")
        if x == y:
            continue
        try:
            same = np.allclose(np.array(x.split(), float), np.array(y.split(), float), rtol=1e-12, atol=0)
        except ValueError:
            same = False
        if not same:
            out.append(f"{here}[@{k}]: {x!r} != {y!r}")
    if len(a) != len(b):
        return [*out, f"{here}: {len(a)} children != {len(b)}"]
    for i, (ca, cb) in enumerate(zip(a, b, strict=True)):
        out += _differences(ca, cb, f"{here}[{i}]")
    return out


def _tree(path: Path, text: str | None = None) -> ET.Element:
    """The XML tree, comments included (a file whose comment holds "--" is not XML: an error)."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    return ET.fromstring(text, parser=parser) if text is not None else ET.parse(path, parser=parser).getroot()


@pytest.mark.parametrize("name", [ARM_FILE, SCENE_FILE])
def test_committed_files_are_what_the_generator_writes(tmp_path, name):
    written = {p.name: p for p in write_model_files(tmp_path)}
    assert set(written) == {ARM_FILE, SCENE_FILE}
    committed = ARM_DIR / name
    assert committed.is_file(), f"{committed} is missing: run {REGENERATE}"
    diff = _differences(_tree(written[name]), _tree(committed))
    assert not diff, f"{committed} drifted from its source ({diff[0]}; {len(diff)} in all): run {REGENERATE}"


def test_the_drift_check_sees_a_changed_number(tmp_path):
    (path,) = (p for p in write_model_files(tmp_path) if p.name == ARM_FILE)
    changed = path.read_text().replace('kp="894"', 'kp="895"', 1)
    assert changed != path.read_text()
    diff = _differences(_tree(path), _tree(path, changed))
    assert len(diff) == 1 and "kp" in diff[0]


def test_the_arm_file_compiles_to_the_model_episodes_run():
    """Every array of the compiled file equals the runtime's (the URDF through arm_spec)."""
    s = Settings().for_world("mujoco")
    runtime = compile_arm(arm_kinematics(s.robot.name, s.robot.limit_set), s.camera).model
    shipped = mujoco.MjModel.from_xml_path(str(ARM_DIR / ARM_FILE))
    compared, differ = 0, []
    for name in dir(runtime):
        value = getattr(runtime, name, None)
        if name.startswith("_") or not isinstance(value, np.ndarray):
            continue
        compared += 1
        other = getattr(shipped, name)
        if value.shape != other.shape or not np.array_equal(value, other):
            differ.append(name)
    assert compared > 100 and not differ, f"{differ} differ: run {REGENERATE}"
    assert shipped.key("home").qpos.tolist() == [0.0] * 6
    assert shipped.actuator("joint1_servo").forcerange.tolist() == [-44.7, 44.7]


# --------------------------------------------------------------------------- every shipped XML
def _warnings_after_one_second(model: mujoco.MjModel, seed: int = 0) -> dict[str, int]:
    """Step 1 s from the ``home`` keyframe (if any) with random targets across each actuator's
    control range; the warnings MuJoCo counted, by name."""
    data = mujoco.MjData(model)
    if model.nkey:
        mujoco.mj_resetDataKeyframe(model, data, 0)
    rng = np.random.default_rng(seed)
    lo, hi = model.actuator_ctrlrange.T
    limited = model.actuator_ctrllimited.astype(bool)
    while data.time < 1.0:
        data.ctrl[:] = np.where(limited, rng.uniform(lo, hi), rng.uniform(-1.0, 1.0, model.nu))
        mujoco.mj_step(model, data)
    return {mujoco.mjtWarning(i).name: int(w.number) for i, w in enumerate(data.warning) if w.number}


def test_the_shipped_xml_files_are_found():
    names = {p.relative_to(models_dir()).as_posix() for p in SHIPPED}
    assert {"manipulator_h/manipulator_h.xml", "manipulator_h/scene.xml"} <= names


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.relative_to(models_dir()).as_posix())
def test_every_shipped_xml_compiles_and_steps_one_second_without_warnings(path):
    model = mujoco.MjModel.from_xml_path(str(path))
    assert model.nu == 6 and model.camera("eye_in_hand").id >= 0
    assert _warnings_after_one_second(model) == {}


def test_the_warning_check_counts_warnings(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo logs the warning to MUJOCO_LOG.TXT in the working folder
    model = mujoco.MjModel.from_xml_path(str(ARM_DIR / SCENE_FILE))
    model.actuator_ctrllimited[:] = 0  # targets of ±1 rad on top of a NaN: MuJoCo warns
    data = mujoco.MjData(model)
    data.ctrl[:] = np.nan
    mujoco.mj_step(model, data)
    assert data.warning[mujoco.mjtWarning.mjWARN_BADCTRL].number > 0


# --------------------------------------------------------------------------- the wheel
def test_the_wheel_build_ships_the_models_where_importlib_resources_finds_them(tmp_path):
    """setup.py's build_py puts models/ into the package; the package then reads them there."""
    if not (REPO / "setup.py").is_file():
        pytest.skip("not a source checkout")
    lib = tmp_path / "lib"
    subprocess.run(
        [sys.executable, "setup.py", "-q", "egg_info", "--egg-base", str(tmp_path), "build_py",
         "--build-lib", str(lib)],
        cwd=REPO, check=True, capture_output=True,
    )  # fmt: skip
    shipped = lib / "bve_mj" / "models" / "manipulator_h"
    assert {p.name for p in shipped.iterdir()} >= {"manipulator_h.urdf", ARM_FILE, SCENE_FILE, "README.md"}
    code = "from bve_mj.robot.description import models_dir; print(models_dir())"
    env = {**os.environ, "PYTHONPATH": str(lib)}
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert Path(out.stdout.strip()) == lib / "bve_mj" / "models"


# --------------------------------------------------------------------------- bve-mj scene
def test_scene_round_trip_is_the_episode_scene_and_loads_on_its_own(tmp_path, capsys):
    config = tmp_path / "scene.toml"
    config.write_text('[scene]\nplants = 3\ntrusses = 2\nfruit_type = "cherry"\n')
    out = tmp_path / "greenhouse"
    assert main(["scene", "--seed", "3", "--config", str(config), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"wrote {out / SCENE_FILE}" in printed and f"--mjcf={out / SCENE_FILE}" in printed

    runtime = start_episode(episode_settings(load_settings(config)), 3).model
    moved = tmp_path / "elsewhere"  # self-contained: every path relative to the folder
    shutil.move(out, moved)
    loaded = mujoco.MjModel.from_xml_path(str(moved / SCENE_FILE))
    for count in ("nbody", "ngeom", "nmesh", "ntex", "nmat", "nlight", "ncam", "nu"):
        assert getattr(loaded, count) == getattr(runtime, count), count
    for field in ("geom_pos", "geom_size", "geom_rgba", "geom_matid", "mesh_vert", "tex_data", "light_dir"):
        assert np.array_equal(getattr(loaded, field), getattr(runtime, field)), field
    assert loaded.ntex >= 4 and loaded.nmesh > 10
    assert _tree(moved / SCENE_FILE).tag == "mujoco"  # well-formed XML, its comment included
    manifest = json.loads((moved / MANIFEST).read_text())
    assert manifest["seed"] == 3 and SCENE_FILE in manifest["files"]
    assert sorted(manifest["files"]) == sorted(
        p.relative_to(moved).as_posix() for p in moved.rglob("*") if p.is_file() and p.name != MANIFEST
    )


def test_scene_replaces_its_own_folder_and_keeps_everything_else(tmp_path, capsys):
    out = tmp_path / "s"
    config = tmp_path / "small.toml"
    config.write_text("[scene]\nplants = 2\ntrusses = 1\n")
    assert main(["scene", "--seed", "1", "--config", str(config), "--out", str(out)]) == 0
    (out / "notes.txt").write_text("mine")
    first = json.loads((out / MANIFEST).read_text())["files"]
    assert main(["scene", "--seed", "2", "--config", str(config), "--out", str(out)]) == 0
    second = json.loads((out / MANIFEST).read_text())["files"]
    assert (out / "notes.txt").read_text() == "mine"
    on_disk = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()}
    assert on_disk == {*second, MANIFEST, "notes.txt"}  # the first scene's other files are gone
    assert json.loads((out / MANIFEST).read_text())["seed"] == 2 and first
    # a file the manifest does not claim is never overwritten
    doc = json.loads((out / MANIFEST).read_text())
    doc["files"].remove(SCENE_FILE)
    (out / MANIFEST).write_text(json.dumps(doc))
    before = (out / SCENE_FILE).read_bytes()
    assert main(["scene", "--seed", "3", "--config", str(config), "--out", str(out)]) == 2
    assert "scene.xml" in capsys.readouterr().err and (out / SCENE_FILE).read_bytes() == before


@pytest.mark.parametrize(
    ("argv", "field"),
    [
        (["--seed", "-1"], "seed"),
        (["--seed", "x"], "seed"),
        (["--config", "/no/such/file.toml"], "config"),
        ([], "--out"),
    ],
)
def test_scene_bad_input_exits_2_with_one_line(tmp_path, capsys, argv, field):
    out = [] if field == "--out" else ["--out", str(tmp_path / "s")]
    assert main(["scene", *argv, *out]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and field in err
    assert not (tmp_path / "s").exists()


def test_scene_refuses_a_folder_it_did_not_write(tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "scene.xml").write_text("<mujoco/>")
    assert main(["scene", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("bve-mj: error: out:")
    assert [p.name for p in out.iterdir()] == ["scene.xml"] and (out / "scene.xml").read_text() == "<mujoco/>"
    file = tmp_path / "a_file"
    file.write_text("x")
    assert main(["scene", "--out", str(file)]) == 2
    assert "out" in capsys.readouterr().err and file.read_text() == "x"
