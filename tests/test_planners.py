"""Planned viewpoints satisfy every constraint; infeasibility is always flagged."""

import dataclasses

import numpy as np
import pytest

from bve_mj.config import Settings
from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.estimation import Belief
from bve_mj.planning import (
    BvePlanner,
    CirclePlanner,
    FixedViewsPlanner,
    RandomPlanner,
    StepLimit,
    build_constraints,
)

TOL = 1e-6
CASES = 200


def random_case(rng, settings=None):
    """A random belief, experiment and camera: half near a feasible point, half anywhere."""
    settings = settings or Settings()
    experiment = EXPERIMENTS[f"E{rng.integers(1, 5)}"]
    A = rng.standard_normal((3, 3)) * 0.04
    while True:
        mean = rng.uniform(-1, 1, 3)
        belief = Belief(mean, A @ A.T + 1e-4 * np.eye(3))
        if rng.random() < 0.5:
            return belief, rng.uniform(-2, 2, 3), experiment
        task = build_constraints(experiment.constraints, settings, mean)
        points = rng.uniform(-0.7, 0.7, (400, 3)) + np.array([0.0, 0.0, 0.159])
        ok = [x for x in points if max(g.value(x) for g in task) <= 0.0]
        if ok:
            return belief, ok[0] + rng.uniform(-0.05, 0.05, 3), experiment


def check_plan(plan, settings, experiment, belief, camera):
    task = build_constraints(experiment.constraints, settings, belief.mean)
    step = StepLimit(camera, settings.step_m)
    assert np.all(np.isfinite(plan.p_world_camera))
    assert step.value(plan.p_world_camera) <= TOL, "the step limit always holds"
    worst = max(g.value(plan.p_world_camera) for g in task)
    if plan.feasible:
        assert plan.status in ("optimal", "best_feasible")
        assert worst <= TOL, f"plan flagged feasible violates a constraint by {worst}"
    else:
        assert plan.status == "restoring"
        assert worst > 0.0
        # restoring never makes things worse than staying put
        assert worst <= max(0.0, *(g.value(camera) for g in task)) + TOL
    return plan.feasible


@pytest.mark.parametrize("optimiser", ["slsqp", "trust-constr"])
@pytest.mark.parametrize("loss", ["dispersion", "max_eigenvalue"])
def test_bve_viewpoints_satisfy_every_constraint(loss, optimiser):
    rng = np.random.default_rng(2024)
    settings = Settings()
    settings = dataclasses.replace(
        settings, planner=dataclasses.replace(settings.planner, optimiser=optimiser)
    )
    feasible = 0
    for _ in range(CASES):
        belief, camera, experiment = random_case(rng)
        planner = BvePlanner(settings, loss, experiment.constraints)
        plan = planner.plan(belief, camera, 1)
        feasible += check_plan(plan, settings, experiment, belief, camera)
    assert feasible >= CASES // 3  # the check above must have seen many feasible plans


def test_bve_is_no_worse_than_its_seed_points():
    rng = np.random.default_rng(7)
    settings = Settings()
    for _ in range(50):
        belief, camera, experiment = random_case(rng)
        planner = BvePlanner(settings, "dispersion", experiment.constraints)
        objective = planner.objective(belief, 1)  # before plan(): it fuses the chosen view
        plan = planner.plan(belief, camera, 1)
        if not plan.feasible:
            continue
        task = build_constraints(experiment.constraints, settings, belief.mean)
        for d in np.eye(3):
            for x in (camera + 0.18 * d, camera - 0.18 * d, camera):
                if max(g.value(x) for g in task) <= 0.0:
                    assert plan.loss <= objective.value(x) + 1e-9


def test_optimisers_agree_on_the_optimum():
    rng = np.random.default_rng(11)
    base = Settings()
    tc = dataclasses.replace(base, planner=dataclasses.replace(base.planner, optimiser="trust-constr"))
    close = total = 0
    for _ in range(40):
        belief, camera, experiment = random_case(rng)
        a = BvePlanner(base, "dispersion", experiment.constraints).plan(belief, camera, 1)
        b = BvePlanner(tc, "dispersion", experiment.constraints).plan(belief, camera, 1)
        if a.feasible and b.feasible:
            total += 1
            close += abs(a.loss - b.loss) <= 1e-3 * max(1.0, abs(a.loss))
    assert total >= 10 and close >= 0.9 * total


@pytest.mark.parametrize("kind", ["random", "circle", "fixed"])
def test_baselines_satisfy_every_constraint(kind):
    rng = np.random.default_rng(99)
    settings = Settings()
    feasible = 0
    for _ in range(CASES):
        belief, camera, experiment = random_case(rng)
        if kind == "random":
            planner = RandomPlanner(settings, experiment.constraints, np.random.default_rng(1))
        elif kind == "circle":
            planner = CirclePlanner(settings, experiment.constraints)
        else:
            planner = FixedViewsPlanner(settings, experiment.constraints)
        feasible += check_plan(planner.plan(belief, camera, 1), settings, experiment, belief, camera)
    assert feasible >= CASES // 3


def test_the_fixed_views_are_three_collinear_points_visited_in_turn_within_the_step_limit():
    """Unconstrained but for the step: left, (through the centre) right, centre, left again;
    the line horizontal and across the view direction, the views a step apart."""
    settings = Settings()
    k = np.array([0.5, 0.1, 0.4])
    start = k + np.array([-0.3, 0.0, 0.05])
    planner = FixedViewsPlanner(settings, ())
    left, right, centre = planner.views(k, start)
    assert np.allclose(centre, start)
    assert np.allclose(left - centre, centre - right)  # collinear, symmetric
    assert np.isclose(np.linalg.norm(left - centre), settings.step_m)
    assert abs((left - centre)[2]) < 1e-12 and abs((left - centre) @ (k - start)) < 1e-12
    belief = Belief(k, 1e-4 * np.eye(3))
    camera, path = start, []
    for i in range(1, 7):
        plan = planner.plan(belief, camera, i)
        assert np.linalg.norm(plan.p_world_camera - camera) <= settings.step_m + 1e-6
        assert np.allclose(plan.p_world_target, k)
        camera = plan.p_world_camera
        path.append(camera)
    expected = [left, centre, right, centre, left, centre]  # right is two steps from left
    assert all(np.allclose(a, b, atol=2e-3) for a, b in zip(path, expected, strict=True)), path


def test_consistent_range_planner_looks_along_the_largest_uncertainty():
    """Range-only: the information is e eᵀ/σ², so the best view is along P's major axis."""
    settings = Settings()
    settings = dataclasses.replace(
        settings, planner=dataclasses.replace(settings.planner, planning_model="consistent")
    )
    k = np.array([0.6, 0.0, 0.3])
    camera = k + np.array([-1.0, 0.0, 0.0])  # looking along +x
    belief = Belief(k, np.diag([0.001**2, 0.08**2, 0.01**2]))  # x known, y most uncertain
    plan = BvePlanner(settings, "dispersion", ("band",)).plan(belief, camera, 1)
    e_new = (k - plan.p_world_camera) / np.linalg.norm(k - plan.p_world_camera)
    assert plan.feasible
    assert abs(e_new[1]) > 0.15  # turned towards the y axis (a 0.2 m step at 1 m: ≤ 0.2)
    assert abs(e_new[1]) > 5 * abs(e_new[2])


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0)))


def test_bve_stops_proposing_a_view_that_measured_nothing():
    """A view that failed (the target hidden from there) is worth little afterwards: the BVE
    plans elsewhere, while with the discount off it returns to the same view."""
    settings = Settings()
    k = np.array([0.6, 0.0, 0.3])
    camera = k + np.array([-settings.band_distance_m, 0.0, 0.0])
    belief = Belief(k, np.diag([0.03**2, 0.004**2, 0.004**2]))  # long along the ray seen
    first = BvePlanner(settings, "dispersion", ("band",)).plan(belief, camera, 1)
    failed_dir = first.p_world_camera - k
    assert _angle_deg(failed_dir, camera - k) > 10.0  # it moved off the measured ray

    for width, far in ((25.0, True), (0.0, False)):
        s = dataclasses.replace(
            settings, planner=dataclasses.replace(settings.planner, failed_view_width_deg=width)
        )
        planner = BvePlanner(s, "dispersion", ("band",))
        planner.note_failed_view(first.p_world_camera, k)
        again = planner.plan(belief, camera, 2)
        assert again.feasible
        moved = _angle_deg(again.p_world_camera - k, failed_dir)
        assert (moved > 10.0) == far, moved
