"""Robustness: validated settings and model files, missed / false / outlier measurements,
planner and IK failures, NaN guards, clear outcomes, and the fault-injection suite."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from bve_mj.campaigns.runner import run_campaign
from bve_mj.campaigns.spec import CampaignSpec
from bve_mj.cli import main
from bve_mj.config import SECTIONS, FaultConfig, Settings, load_settings, settings_from_dict, with_overrides
from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.errors import ConfigError, EstimationError
from bve_mj.estimation.belief import Belief
from bve_mj.loop.episode import run_episode
from bve_mj.loop.faults import FaultyPlanner, FaultyWorld
from bve_mj.loop.synthetic import sample_scenario
from bve_mj.planning import make_planner
from bve_mj.robot.description import ROBOTS
from bve_mj.robot.kinematics import ArmKinematics
from bve_mj.sim.synthetic import SyntheticWorld
from bve_mj.sim.world import Observation

REPO = Path(__file__).resolve().parents[1]
BAD_VALUES = ["x", [1, 2], {"a": 1}, float("nan"), float("inf"), -1e9, True]


@pytest.mark.parametrize("section", list(SECTIONS))
def test_every_setting_rejects_wrong_types_and_ranges_by_name(section: str) -> None:
    """Each field of each section, given values of the wrong type or range: a ConfigError
    naming the field, never another exception (pairs and lists may legitimately take [1, 2])."""
    cls = SECTIONS[section]
    for f in dataclasses.fields(cls):
        rejected = 0
        for bad in BAD_VALUES:
            try:
                settings_from_dict({section: {f.name: bad}})
            except ConfigError as exc:
                assert exc.field.startswith(section), (f.name, bad, exc.field)
                rejected += 1
        assert rejected >= len(BAD_VALUES) - 2, f"{section}.{f.name} accepts too much"


def test_unknown_keys_suggest_and_cli_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "s.toml"
    cfg.write_text("[faults]\ndrop_pp = 0.3\n")
    with pytest.raises(ConfigError, match="did you mean 'drop_p'"):
        load_settings(cfg)
    bad_files = ("[faults]\ndrop_p = 1.5\n", "[episode]\nexperiment = 5\n",
                 "[scene]\nfruit_radius_m = [1, 2]\n", "not toml [")  # fmt: skip
    for text in bad_files:
        cfg.write_text(text)
        assert main(["episode", "--config", str(cfg), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "error:" in err, err


@pytest.mark.parametrize(("content", "reason"), [("<robot name='x'><link", "valid URDF"), (None, "existing")])
def test_corrupt_or_missing_model_files_are_named(tmp_path: Path, content: str | None, reason: str) -> None:
    urdf = tmp_path / "arm.urdf"
    if content is not None:
        urdf.write_text(content)
    robot = dataclasses.replace(ROBOTS["manipulator_h"], urdf=str(urdf))
    with pytest.raises(ConfigError, match=rf"robot\.urdf: .*{reason}"):
        ArmKinematics(robot)


# --------------------------------------------------------------------------- the loop, synthetic
GATED = with_overrides(
    Settings(), measurement={"kind": "camera"}, filter={"gate_probability": 0.999}, protocol={"steps": 20}
)


def _episode(settings: Settings, run: int, wrap=None):  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(run)
    scenario = sample_scenario(settings.protocol, rng)
    world = SyntheticWorld(settings.measurement.kind, settings.sigma_c_m2(), scenario, rng)
    planner = make_planner(settings, "dispersion", EXPERIMENTS["E1"].constraints, rng)
    loop_world = wrap(world) if wrap else FaultyWorld(world, settings.faults, np.random.default_rng(run + 1))
    prior = Belief.isotropic(scenario.initial_estimate, settings.filter.initial_sigma_m)
    result = run_episode(loop_world, planner, prior, settings.filter, settings.protocol.steps)
    return scenario, result


def test_fruit_hidden_for_several_views_holds_then_recovers() -> None:
    s = dataclasses.replace(GATED, faults=FaultConfig(hidden_views=(0, 1, 2, 3, 4)))
    for run in range(5):
        scenario, result = _episode(s, run)
        hidden = result.views[:5]
        assert all(not v.measured and v.has("dropped") for v in hidden)
        assert all(np.array_equal(v.belief.mean, result.prior.mean) for v in hidden)  # bounded: unchanged
        assert np.linalg.norm(result.final.mean - scenario.p_world_fruit) < 10e-3
        assert result.final.mahalanobis_sq(scenario.p_world_fruit) < 16.3  # inside the 99.9% ellipsoid


class _FalseFirst:
    """Measures a point 20 cm off the fruit on views 0 and 1 (a red leaf), the fruit after."""

    def __init__(self, world: SyntheticWorld) -> None:
        self.world, self.view = world, 0

    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        return getattr(self.world, name)

    def observe(self, belief: object = None) -> Observation | None:
        obs = self.world.observe()
        self.view += 1
        if obs is not None and self.view <= 2:
            fake = self.world.p_world_fruit + np.array([0.0, 0.2, 0.0])
            return Observation(obs.model.predict(fake), obs.model)
        return obs


def test_early_false_detection_is_recovered_by_the_belief_reset() -> None:
    for run in range(5):
        scenario, result = _episode(GATED, run, _FalseFirst)
        events = [e.kind for v in result.views for e in v.events]
        assert "belief_reset" in events
        assert np.linalg.norm(result.final.mean - scenario.p_world_fruit) < 5e-3


def test_outliers_and_false_detections_are_gated() -> None:
    s = dataclasses.replace(GATED, faults=FaultConfig(outlier_p=0.2, false_p=0.1, drop_p=0.3))
    injected = gated = 0
    for run in range(10):
        scenario, result = _episode(s, run)
        for v in result.views[2:]:  # once the belief is narrow, a gross error must not pass
            if v.has("outlier") or v.has("false_detection"):
                injected += 1
                gated += not v.accepted
        assert np.linalg.norm(result.final.mean - scenario.p_world_fruit) < 10e-3
    assert injected >= 10 and gated >= 0.8 * injected


def test_planner_failures_fall_back_to_holding() -> None:
    s = dataclasses.replace(GATED, faults=FaultConfig(planner_failure_p=1.0))
    rng = np.random.default_rng(0)
    scenario = sample_scenario(s.protocol, rng)
    world = SyntheticWorld(s.measurement.kind, s.sigma_c_m2(), scenario, rng)
    planner = FaultyPlanner(make_planner(s, "dispersion", ("band",), rng), 1.0, rng)
    result = run_episode(world, planner, Belief.isotropic(scenario.initial_estimate, 0.1), s.filter, 5)
    assert [v.plan_status for v in result.views[1:]] == ["fallback"] * 5
    assert all(np.allclose(v.p_world_camera, scenario.p_world_camera_start) for v in result.views)
    assert all(
        v.events and v.events[0].kind == "planner_failed" and v.events[0].detail for v in result.views[1:]
    )


def test_nan_never_enters_the_belief_and_the_step_is_named() -> None:
    class NanAtView2(_FalseFirst):
        def observe(self, belief: object = None) -> Observation | None:
            obs = self.world.observe()
            self.view += 1
            if obs is not None and self.view == 3:
                return Observation(np.full_like(obs.z, np.nan), obs.model)
            return obs

    with pytest.raises(EstimationError, match=r"view 2: .*NaN"):
        _episode(GATED, 0, NanAtView2)


# --------------------------------------------------------------------------- outcomes, MuJoCo
def test_out_of_reach_and_never_visible_are_outcomes_with_exit_3(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    far = tmp_path / "far.toml"
    far.write_text("[scene]\nrow_x_m = 2.5\ntarget_x_m = [2.2, 2.3]\n")
    blind = tmp_path / "blind.toml"
    blind.write_text("[detector]\nmin_area_px = 1000000\n")
    assert main(["episode", "--config", str(far), "--quiet", "--json", str(tmp_path / "far.json")]) == 3
    assert "outcome: unreachable" in capsys.readouterr().out
    assert main(["episode", "--config", str(blind), "--quiet", "--views", "2"]) == 3
    assert "outcome: never_detected" in capsys.readouterr().out


# --------------------------------------------------------------------------- the suite
def test_fault_injection_suite_60_mujoco_episodes(tmp_path: Path) -> None:
    """60 short seeded MuJoCo episodes with the faults of examples/scenarios/faults.toml (200,
    then 100, until the suite's time passed 10 minutes; the figures below are of 200;
    ``bve-mj campaign --config examples/scenarios/faults.toml`` runs the full campaign).

    In the sphere scene this gave median 0.54, p95 1.61, max 67.65 mm (a wrong-radius range
    bias held after failures repeated one view). In the realistic scene (spheroid fruit, shape
    index 0.8-0.95, touching trusses) with the arc-grouping detector: median 1.83, p95 6.23,
    max 11.21 mm; the median and p95 are the unknown size and shape of each fruit, a per-fruit
    bias the filter still treats as noise (the size issue puts the radius in the state). With
    the prior scaled to the fruit, the failed-view discount and the arc jackknife: median
    0.57, p95 2.99, max 26.98 mm, the max an episode that ended ``max_views`` (NEES 4.0: its
    covariance said so); converged and stable episodes stay under 25 mm. With the radius in
    the state (200 episodes): median 0.51, p95 1.92, max 34.94 mm (unfinished); 0 of 184
    converged episodes outside their 99.9% ellipsoid (38 of 153 before). An
    episode may end ``stalled`` (camera stopped moving) or ``unreliable`` (estimate not
    supported by the measurements): honest outcomes, never a crash."""
    settings = load_settings(REPO / "examples" / "scenarios" / "faults.toml")
    assert settings.faults.drop_p == 0.3 and settings.sensor.encoder_noise_rad > 0
    spec = CampaignSpec(experiments=("E1", "E5"), worlds=("mujoco",), measurements=("camera",), runs=30)
    result = run_campaign(settings, spec, tmp_path, workers=2)
    rows = result.rows
    assert len(rows) == 60
    assert not result.crashed, result.crashed[:3]
    outcomes = {r["outcome"] for r in rows}
    allowed = {"converged", "stable", "max_views", "never_detected", "ambiguous", "stalled", "unreliable"}
    assert outcomes <= allowed
    assert all(r["belief_finite"] for r in rows)
    assert max(r["joint_limit_violation_rad"] for r in rows) <= 1e-3
    radius = settings.scene.radius_range_m[1]
    assert min(r["min_camera_fruit_distance_m"] for r in rows) > radius
    errors = np.array([r["error_mm"] for r in rows])
    initial_bound_mm = 1e3 * settings.episode.initial_error_m * np.sqrt(3.0)
    assert errors.max() <= initial_bound_mm  # bounded: never worse than the prior's worst case
    assert np.median(errors) < 3.0 and np.percentile(errors, 95) < 10.0
    claimed = [r["error_mm"] for r in rows if r["outcome"] in ("converged", "stable")]
    assert claimed and max(claimed) < 25.0  # an episode that did not finish may be further off
    counts: dict[str, int] = {}
    for r in rows:
        for k, n in r["events"].items():
            counts[k] = counts.get(k, 0) + n
    for kind in ("dropped", "false_detection", "outlier", "ik_failure", "planner_failed"):
        assert counts.get(kind, 0) > 0, (kind, counts)
    by_outcome = {o: sum(r["outcome"] == o for r in rows) for o in sorted(outcomes)}
    print(f"\nfault suite: {len(rows)} episodes, events {counts}, outcomes {by_outcome}, final error "
          f"median {np.median(errors):.2f} mm, p95 {np.percentile(errors, 95):.2f} mm, "
          f"max {errors.max():.2f} mm")  # fmt: skip


@pytest.mark.parametrize("kind", ["second_red_fruit", "red_leaf"])
def test_a_second_red_blob_in_the_rendered_scene_does_not_capture_the_estimate(kind: str) -> None:
    import mujoco

    from bve_mj.loop.mujoco import run_mujoco_episode
    from bve_mj.sim.scene_model import Fruit

    target = Fruit("target", np.array([0.42, 0.0, 0.2]), 0.033, "red")
    settings = with_overrides(Settings(), measurement={"kind": "camera"}, episode={"views": 10})
    others: tuple[Fruit, ...] = ()
    edit = None
    if kind == "second_red_fruit":
        others = (Fruit("ripe_neighbour", np.array([0.43, 0.085, 0.17]), 0.035, "red"),)
    else:

        def edit(spec: mujoco.MjSpec) -> None:  # a reddish leaf hanging beside the fruit
            spec.worldbody.add_geom(
                name="red_leaf", type=mujoco.mjtGeom.mjGEOM_ELLIPSOID, size=[0.003, 0.03, 0.05],
                pos=target.centre_m + np.array([-0.03, -0.07, 0.02]), rgba=[0.75, 0.08, 0.05, 1.0],
                contype=0, conaffinity=0, group=1,
            )  # fmt: skip

    import cv2

    from bve_mj.config import DetectorConfig
    from bve_mj.perception.masks import red_mask

    class CountRedBlobs:  # a recorder that checks the second red blob is really in view
        def attach(self, world, prior, shape=None):  # type: ignore[no-untyped-def]
            self.world, self.counts = world, []

        def on_step(self, sim_time: float) -> None:
            pass

        def on_view(self, record) -> None:  # type: ignore[no-untyped-def]
            n, _, stats, _ = cv2.connectedComponentsWithStats(
                red_mask(self.world.last.image, DetectorConfig())
            )
            self.counts.append(sum(stats[i, cv2.CC_STAT_AREA] >= 25 for i in range(1, n)))

    for seed in (0, 1):
        rec = CountRedBlobs()
        ep = run_mujoco_episode(settings, seed, target=target, distractors=others, edit=edit, recorder=rec)
        assert max(rec.counts) >= 2, rec.counts
        assert ep.final_error_mm < 10.0, (kind, seed, ep.final_error_mm, ep.result.outcome)


def test_the_loop_tells_the_planner_of_every_view_that_measured_nothing() -> None:
    """Views dropped (nothing measured) are reported to a planner that learns from them,
    with the camera position and the estimate it looked at; measured views are not."""
    s = dataclasses.replace(GATED, faults=FaultConfig(drop_p=0.5))
    rng = np.random.default_rng(3)
    scenario = sample_scenario(s.protocol, rng)
    world = FaultyWorld(SyntheticWorld(s.measurement.kind, s.sigma_c_m2(), scenario, rng), s.faults, rng)
    inner = make_planner(s, "dispersion", ("band",), rng)
    told: list[tuple[np.ndarray, np.ndarray]] = []

    class Spy:
        def plan(self, belief: Belief, p_world_camera: np.ndarray, iteration: int):  # type: ignore[no-untyped-def]
            return inner.plan(belief, p_world_camera, iteration)

        def note_failed_view(self, p_world_camera: np.ndarray, p_world_target: np.ndarray) -> None:
            told.append((p_world_camera.copy(), p_world_target.copy()))

    result = run_episode(world, Spy(), Belief.isotropic(scenario.initial_estimate, 0.1), s.filter, 8)
    failed = [v for v in result.views if not v.accepted]
    assert failed and len(told) == len(failed)
    for v, (camera, _) in zip(failed, told, strict=True):
        np.testing.assert_allclose(camera, v.p_world_camera)
