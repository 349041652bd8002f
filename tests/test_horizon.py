"""The receding-horizon BVE: its objective's gradient, its constraints, and a plan no worse
than the greedy roll-out it starts from."""

import numpy as np
import pytest

from bve_mj.config import Settings, with_overrides
from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.estimation import Belief
from bve_mj.planning import BvePlanner, CameraInformation, max_violation
from bve_mj.planning.horizon import ChainedStep, HorizonObjective, horizon_constraints
from bve_mj.planning.size_information import SizeInformation
from tests.conftest import finite_difference


@pytest.mark.parametrize("loss", ["dispersion", "max_eigenvalue"])
@pytest.mark.parametrize("dim", [3, 4])
def test_horizon_objective_gradient(rng, loss, dim):
    info = (
        CameraInformation(np.diag([0.09**2, 0.002**2, 0.002**2]))
        if dim == 3
        else SizeInformation((2e-7, 1e-9), (1e-7, 2e-9))
    )
    for _ in range(10):
        x = np.concatenate([rng.uniform(-0.3, 0.3, 3), [0.03]])[:dim]
        A = rng.normal(size=(dim, dim))
        Lo = np.linalg.inv(0.02**2 * (A @ A.T + 0.3 * np.eye(dim)))
        z = np.concatenate([x[:3] + 0.3 * d / np.linalg.norm(d) for d in rng.normal(size=(3, 3))])
        obj = HorizonObjective(info, x, Lo, loss, 0.5)
        _, g = obj.value_and_gradient(z)
        fd = finite_difference(lambda zz, o=obj: o.value_and_gradient(zz)[0], z, 1e-7)
        np.testing.assert_allclose(g, fd, rtol=1e-4, atol=1e-7 * max(1.0, np.abs(g).max()))


def test_chained_step_gradient(rng):
    z = rng.normal(size=9)
    c = ChainedStep(2, 3, 0.1)
    np.testing.assert_allclose(c.gradient(z), finite_difference(c.value, z), atol=1e-7)
    assert c.value(z) == pytest.approx(np.sum((z[6:9] - z[3:6]) ** 2) - 0.01)


def _planner(horizon):
    s = with_overrides(Settings(), measurement={"kind": "camera"}, planner={"horizon": horizon})
    s = s.for_world("synthetic")
    e = EXPERIMENTS["E3"]
    return s, BvePlanner(s, e.loss, e.constraints)


def test_a_horizon_plan_is_feasible_and_no_worse_than_the_greedy_roll_out(rng):
    s, planner = _planner(3)
    checked = 0
    for _ in range(6):
        k = rng.uniform(-0.5, 0.5, 3)
        belief = Belief.isotropic(k, 0.01)
        d = rng.normal(size=3)
        c_now = k + 0.6 * d / np.linalg.norm(d)
        greedy = planner._greedy(belief, c_now, 1, planner.objective(belief, 1))
        if not greedy.feasible:
            continue
        ahead = planner.plan_ahead(belief, c_now, 1, greedy.p_world_camera)
        assert ahead is not None and ahead.shape == (3, 3)
        every = [*planner.task_constraints(k)]
        from bve_mj.planning.constraints import StepLimit

        cons = horizon_constraints([*every, StepLimit(c_now, s.step_m)], 3, s.step_m)
        assert max_violation(cons, ahead.reshape(-1)) <= 1e-6
        # the greedy roll-out, view by view, against the joint plan, on the plan's own objective
        info = planner.information_model()
        obj = HorizonObjective(info, belief.mean, planner.prior_precision(belief), planner.loss)
        roll = [greedy.p_world_camera]
        extra = info.information(roll[0], belief.mean)
        for h in (1, 2):
            nxt = planner._greedy(belief, roll[-1], 1 + h, planner.objective(belief, 1 + h, extra))
            roll.append(nxt.p_world_camera)
            extra = extra + info.information(nxt.p_world_camera, belief.mean)
        assert obj.value(ahead.reshape(-1)) <= obj.value(np.concatenate(roll)) + 1e-9
        checked += 1
    assert checked >= 3


def test_horizon_one_is_the_greedy_bve(rng):
    _, greedy = _planner(1)
    k = np.array([0.2, -0.1, 0.3])
    belief = Belief.isotropic(k, 0.01)
    c_now = k + np.array([0.5, 0.6, 0.2])
    a = greedy.propose(belief, c_now, 1)
    b = greedy._greedy(belief, c_now, 1, greedy.objective(belief, 1))
    np.testing.assert_array_equal(a.p_world_camera, b.p_world_camera)
