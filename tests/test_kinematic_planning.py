"""E5/E10: viewpoints planned with the arm's kinematics are reachable."""

import math

import numpy as np
import pytest

from bve_mj.campaigns.paper import run_synthetic
from bve_mj.config import Settings, with_overrides
from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.estimation import Belief
from bve_mj.planning import build_constraints
from bve_mj.robot import ArmKinematics, KinematicBvePlanner, get_robot, look_at_ik


@pytest.mark.parametrize("experiment", ["E5", "E10"])
def test_planned_viewpoints_are_reachable(experiment):
    settings = Settings()
    e = EXPERIMENTS[experiment]
    kin = ArmKinematics(get_robot("manipulator_h"), "emanual")
    rng = np.random.default_rng(5)
    feasible = 0
    for case in range(12):
        k = np.array([rng.uniform(0.25, 0.6), rng.uniform(-0.4, 0.4), rng.uniform(0.0, 0.6)])
        belief = Belief.isotropic(k + rng.uniform(-0.05, 0.05, 3), 0.05)
        planner = KinematicBvePlanner(settings, e.loss, e.constraints, kin, kin.home, "joint", rng)
        camera = kin.camera_pose(kin.home)[0]
        for i in range(1, 4):
            plan = planner.plan(belief, camera, i)
            assert plan.q is not None and kin.within_limits(plan.q)
            p, R = kin.camera_pose(plan.q)
            np.testing.assert_allclose(p, plan.p_world_camera, atol=1e-9)  # the plan is the FK of q
            assert np.linalg.norm(p - camera) <= settings.step_m + 1e-6
            if plan.feasible:
                feasible += 1
                d = (plan.p_world_target - p) / np.linalg.norm(plan.p_world_target - p)
                assert math.acos(min(1.0, R[:, 0] @ d)) <= 1e-3  # looks at the estimate
                task = build_constraints(e.constraints, settings, belief.mean)
                assert max(g.value(p) for g in task) <= 1e-6
                ik = look_at_ik(kin, p, plan.p_world_target, plan.q)  # an independent IK agrees
                assert ik.success
            camera = p
        del case
    assert feasible >= 24


def test_e5_runs_report_reachability():
    s = with_overrides(Settings(), protocol={"steps": 8})
    rec = run_synthetic(s, EXPERIMENTS["E5"], 0, 0)
    assert np.all(np.isfinite(rec["estimate_m"]))
    kin = ArmKinematics(get_robot("manipulator_h"), "emanual")
    # E5 starts at the arm's home pose, not at the protocol's unreachable random start
    assert len(rec["plan_ms"]) == 8
    assert rec["ever_feasible"] or rec["restoring_steps"] == 8
    assert np.linalg.norm(kin.camera_pose(kin.home)[0]) < 1.0


def test_joint_limit_barrier_gradient_matches_finite_differences():
    from bve_mj.robot import arm_kinematics
    from bve_mj.robot.joint_problem import LimitMargin

    kin = arm_kinematics("manipulator_h", "emanual")
    barrier = LimitMargin(kin, 1.0)
    rng = np.random.default_rng(3)
    lo, hi = kin.limits.lower, kin.limits.upper
    for _ in range(20):
        q = lo + (hi - lo) * rng.choice([0.02, 0.05, 0.5, 0.93, 0.97], kin.nq)
        value, grad = barrier(q)
        fd = np.array([(barrier(q + e)[0] - barrier(q - e)[0]) / 2e-7 for e in np.eye(kin.nq) * 1e-7])
        np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-6)
        assert value >= 0.0
    mid = 0.5 * (lo + hi)
    assert barrier(mid) == (0.0, pytest.approx(np.zeros(kin.nq)))


def test_joint_look_at_jacobian_matches_finite_differences():
    """The joint-space planner's look-at terms h(q) = (y_C·d, z_C·d, x_C·d) and ∂h/∂q."""
    from bve_mj.robot import arm_kinematics
    from bve_mj.robot.joint_problem import JointProblem

    kin = arm_kinematics("manipulator_h", "emanual")
    rng = np.random.default_rng(5)
    lo, hi = kin.limits.lower, kin.limits.upper
    for _ in range(10):
        q = lo + (hi - lo) * rng.uniform(0.3, 0.7, kin.nq)
        k_hat = kin.camera_pose(q)[0] + rng.normal(0.0, 0.2, 3)
        _, dh = JointProblem(kin, k_hat).look_at(q)

        def h(qq, k_hat=k_hat):
            return JointProblem(kin, k_hat).look_at(qq)[0]

        fd = np.column_stack([(h(q + e) - h(q - e)) / 2e-6 for e in np.eye(kin.nq) * 1e-6])
        np.testing.assert_allclose(dh, fd, rtol=1e-5, atol=1e-7)


def test_joint_limit_barrier_float_path_rounds_as_the_array_code():
    """The barrier is computed joint by joint on floats for speed: the same bits as on arrays
    (value, gradient, signs of zeros, NaN), at the limits, outside them and in the middle."""
    from bve_mj.robot import arm_kinematics
    from bve_mj.robot.joint_problem import LimitMargin

    kin = arm_kinematics("manipulator_h", "emanual")
    barrier = LimitMargin(kin, 0.7)
    rng = np.random.default_rng(11)
    lo, hi = kin.limits.lower, kin.limits.upper
    qs = [lo + (hi - lo) * rng.uniform(-0.1, 1.1, kin.nq) for _ in range(2000)]
    qs += [lo.copy(), hi.copy(), 0.5 * (lo + hi), np.full(kin.nq, np.nan)]
    for q in qs:
        value, gradient = barrier.lazy(q)
        ref_value, ref_gradient = barrier._lazy_arrays(q)
        assert value == ref_value or (np.isnan(value) and np.isnan(ref_value))
        g, ref = gradient(), ref_gradient()
        assert np.array_equal(g, ref, equal_nan=True) and np.array_equal(np.signbit(g), np.signbit(ref))


def test_joint_problem_cache_follows_q():
    """The joint problem caches the pose, h and ∂h/∂q of the last q: whatever the order of the
    calls (SLSQP asks for values and Jacobians at points it revisits), each answer is the one
    a fresh problem gives at that q, and the configuration SLSQP mutates in place is copied."""
    from bve_mj.robot import arm_kinematics
    from bve_mj.robot.joint_problem import JointProblem

    kin = arm_kinematics("manipulator_h", "emanual")
    rng = np.random.default_rng(8)
    lo, hi = kin.limits.lower, kin.limits.upper
    k_hat = kin.camera_pose(kin.home)[0] + np.array([0.3, 0.1, -0.1])
    cached = JointProblem(kin, k_hat)
    x = np.array(kin.home, dtype=float)  # one array changed in place, as SLSQP's x is
    for step in range(40):
        if step % 3:
            x[:] = lo + (hi - lo) * rng.uniform(0.2, 0.8, kin.nq)
        fresh = JointProblem(kin, k_hat)
        calls = [cached.look_jacobian, cached.look] if step % 2 else [cached.look, cached.look_jacobian]
        got = {f.__name__: f(x).copy() for f in calls}
        assert np.array_equal(got["look"], fresh.look(x.copy()))
        assert np.array_equal(got["look_jacobian"], fresh.look_jacobian(x.copy()))
        for a, b in zip(cached.at(x), fresh.at(x.copy()), strict=True):
            assert np.array_equal(a, b)


def test_upright_preference_gradient_matches_finite_differences():
    from bve_mj.robot import arm_kinematics
    from bve_mj.robot.joint_problem import UprightPreference

    kin = arm_kinematics("manipulator_h", "emanual")
    pref = UprightPreference(0.3)
    rng = np.random.default_rng(8)

    def value(q):
        _, R, J = kin.camera_pose_and_jacobian(q)
        return pref.lazy(R, J)[0]

    for _ in range(20):
        q = kin.random_configuration(rng)
        _, R, J = kin.camera_pose_and_jacobian(q)
        v, grad = pref.lazy(R, J)
        fd = np.array([(value(q + e) - value(q - e)) / 2e-6 for e in np.eye(kin.nq) * 1e-6])
        np.testing.assert_allclose(grad(), fd, rtol=1e-5, atol=1e-7)
        assert 0.0 <= v <= 2 * pref.weight


def test_planned_views_are_upright_where_the_arm_allows():
    """The joint-space BVE spends the roll neither its loss nor its constraints see on an
    upright image; with upright_weight = 0 the roll is whatever the optimiser leaves."""
    from bve_mj.robot.ik import image_roll_rad

    e = EXPERIMENTS["E5"]
    kin = ArmKinematics(get_robot("manipulator_h"), "emanual")
    rolls = {}
    for weight in (0.1, 0.0):
        settings = with_overrides(Settings(), planner={"upright_weight": weight})
        rng = np.random.default_rng(5)
        rolls[weight] = []
        for _ in range(8):
            k = np.array([rng.uniform(0.25, 0.5), rng.uniform(-0.3, 0.3), rng.uniform(0.1, 0.4)])
            belief = Belief.isotropic(k, 0.02)
            planner = KinematicBvePlanner(settings, e.loss, e.constraints, kin, kin.home, "joint", rng)
            camera = kin.camera_pose(kin.home)[0]
            for i in range(1, 4):
                plan = planner.plan(belief, camera, i)
                camera = plan.p_world_camera
                roll = image_roll_rad(kin.camera_pose(plan.q)[1])
                if plan.feasible and roll is not None:
                    rolls[weight].append(abs(roll))
    assert len(rolls[0.1]) >= 12
    # measured: median 14° with the preference (the joint limits leave some rolls), 97° without
    assert np.median(rolls[0.1]) <= math.radians(25.0)
    assert np.median(rolls[0.0]) > math.radians(60.0)


def test_a_joint_space_run_halts_where_its_objective_stalls_feasible_or_sticks_infeasible():
    from bve_mj.robot.planner import _STALL_ITERATIONS, _stalled

    q = np.zeros(6)
    falling = _stalled(lambda q: True)
    assert not any(falling(q, -50.0 - k) for k in range(30))  # one nat an iteration: never
    flat = _stalled(lambda q: True)
    halts = [flat(q, -50.0 - 1e-6 * k) for k in range(_STALL_ITERATIONS + 2)]
    assert halts == [False] * _STALL_ITERATIONS + [True, True]  # after the window of iterations
    creeping = _stalled(lambda q: False)  # infeasible, still moving a little: never
    assert not any(creeping(q, -50.0 - 1e-6 * k) for k in range(30))
    stuck = _stalled(lambda q: False)  # infeasible, the same point iteration after iteration
    halts = [stuck(q, -50.0) for _ in range(_STALL_ITERATIONS + 2)]
    assert halts == [False] * _STALL_ITERATIONS + [True, True]


@pytest.mark.parametrize("economical", [True, False])
def test_the_second_start_runs_only_where_the_first_run_stays_near_the_view_just_taken(
    monkeypatch, economical
):
    """``economical``: the first run starts from the current configuration; where it ends
    feasible and three quarters of a step or more from the camera, the seed direction's run
    is skipped; where it does not, the seed direction's run follows (where a seed direction
    meets the task's constraints: not always). Not economical: it always follows."""
    import bve_mj.robot.planner as planner_module
    from bve_mj.planning.bve import SEED_DIRECTIONS

    runs: list[np.ndarray] = []  # each look-at run's end configuration (not the restoring one)
    real = planner_module.minimize_slsqp

    def counted(*args, **kwargs):
        res = real(*args, **kwargs)
        if kwargs.get("eq"):
            runs.append(res.x)
        return res

    monkeypatch.setattr(planner_module, "minimize_slsqp", counted)
    settings = Settings()
    e = EXPERIMENTS["E5"]
    kin = ArmKinematics(get_robot("manipulator_h"), "emanual")
    rng = np.random.default_rng(3)
    seen = {True: 0, False: 0}  # plans whose first run left the view just taken, and the others
    for _ in range(6):
        k = np.array([rng.uniform(0.3, 0.5), rng.uniform(-0.3, 0.3), rng.uniform(0.1, 0.5)])
        belief = Belief.isotropic(k, 0.05)
        planner = KinematicBvePlanner(
            settings, e.loss, e.constraints, kin, kin.home, "joint", rng, economical
        )
        camera = kin.camera_pose(kin.home)[0]
        task = build_constraints(e.constraints, settings, belief.mean)
        for i in range(1, 4):
            runs.clear()
            plan = planner.plan(belief, camera, i)
            p, R = kin.camera_pose(kin.clip(runs[0]))
            d = (k - p) / np.linalg.norm(k - p)
            feasible = (
                math.acos(min(1.0, R[:, 0] @ d)) <= 1e-3
                and max(g.value(p) for g in task) <= settings.planner.feasibility_tol
                and np.linalg.norm(p - camera) <= settings.step_m + 1e-6
            )
            left = feasible and np.linalg.norm(p - camera) >= 0.75 * settings.step_m
            seeds = camera + 0.9 * settings.step_m * SEED_DIRECTIONS  # the seed directions' points
            second = any(max(g.value(x) for g in task) <= settings.planner.feasibility_tol for x in seeds)
            assert len(runs) == (1 if (left and economical) or not second else 2)
            seen[left] += 1
            camera = plan.p_world_camera
    assert seen[True] and seen[False]  # both ways exercised
