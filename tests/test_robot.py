"""The arms: Pinocchio/MuJoCo agreement, Jacobians, look-at IK, the MJCF, the reach."""

import math

import mujoco
import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import minimize

from bve_mj.errors import ConfigError
from bve_mj.robot import ROBOTS, ArmKinematics, get_robot, look_at_ik
from bve_mj.sim.arm import compile_arm
from tests.conftest import finite_difference

LIMITS = {"manipulator_h": "emanual", "ur5": "urdf", "panda": "urdf"}


@pytest.fixture(scope="module", params=list(ROBOTS))
def arm(request):
    name = request.param
    kin = ArmKinematics(get_robot(name), LIMITS[name])
    return kin, compile_arm(kin)


def test_pinocchio_and_mujoco_agree_on_the_camera_pose(arm):
    kin, am = arm
    data = mujoco.MjData(am.model)
    rng = np.random.default_rng(0)
    for _ in range(100):
        q = kin.random_configuration(rng)
        data.qpos[am.qpos_adr] = q
        mujoco.mj_kinematics(am.model, data)
        mujoco.mj_camlight(am.model, data)
        p, R = kin.camera_pose(q)
        np.testing.assert_allclose(data.site_xpos[am.camera_site_id], p, atol=1e-6)
        np.testing.assert_allclose(data.site_xmat[am.camera_site_id].reshape(3, 3), R, atol=1e-6)
        # the MuJoCo camera looks along the optical axis (its -z), with up = camera z
        cam = data.cam_xmat[am.camera_id].reshape(3, 3)
        np.testing.assert_allclose(-cam[:, 2], R[:, 0], atol=1e-6)
        np.testing.assert_allclose(cam[:, 1], R[:, 2], atol=1e-6)


def test_camera_jacobian_matches_finite_differences(arm):
    kin, _ = arm
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = kin.random_configuration(rng)
        _, R, J = kin.camera_pose_and_jacobian(q)
        Jv = finite_difference(lambda x: kin.camera_pose(x)[0], q)
        np.testing.assert_allclose(J[:3], Jv, atol=1e-6)
        # angular part: dR/dq_i = [ω_i]× R
        for i in range(kin.nq):
            dR = finite_difference(
                lambda t, i=i, q=q: kin.camera_pose(q + t[0] * np.eye(kin.nq)[i])[1], np.zeros(1)
            )
            w = J[3:, i]
            skew_w = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
            np.testing.assert_allclose(dR[..., 0], skew_w @ R, atol=1e-6)


def test_batched_camera_poses_match_pinocchio(arm):
    kin, _ = arm
    rng = np.random.default_rng(3)
    Q = np.array([kin.random_configuration(rng) for _ in range(50)])
    P, R, J = kin.camera_poses_and_jacobians(Q)
    assert kin._chain is not None  # the NumPy path, not the one-at-a-time fallback
    for i, q in enumerate(Q):
        p, r, j = kin.camera_pose_and_jacobian(q)
        np.testing.assert_allclose(P[i], p, rtol=0, atol=1e-12)
        np.testing.assert_allclose(R[i], r, rtol=0, atol=1e-12)
        np.testing.assert_allclose(J[i], j, rtol=0, atol=1e-12)
    other = ArmKinematics(kin.robot, kin.limit_set)
    other._chain = None  # an arm the NumPy path does not cover: one Pinocchio call each
    for a, b in zip(other.camera_poses_and_jacobians(Q[:5]), (P[:5], R[:5], J[:5]), strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_look_at_residuals_tell_which_starts_solve(arm):
    """The batched solve ends where each single start of the look-at IK ends: the same
    verdict for every start (solved, and worth solving one by one), residuals alike. A start
    that fails wanders for all its iterations, and rounding that differs in the last bit can
    send it elsewhere (with pin 4.1 and mujoco 4.0, one of the 41 failing Manipulator-H starts
    ends at 0.53 where the single solve ends at 0.41, far above the screen's 0.01 either way):
    the rest agree to 1e-6."""
    from bve_mj.loop.start import _WORTH_SOLVING
    from bve_mj.robot.ik import IkOptions, _solve_from, look_at_residuals

    kin, _ = arm
    rng = np.random.default_rng(4)
    n = 60
    starts = np.array([kin.random_configuration(rng) for _ in range(n)])
    cameras, directions = [], []
    for _ in range(n):
        p, R = kin.camera_pose(kin.random_configuration(rng))
        d = R[:, 0] + 0.3 * rng.standard_normal(3)
        cameras.append(p)
        directions.append(d / np.linalg.norm(d))
    opt = IkOptions(restarts=0)
    batched = look_at_residuals(kin, starts, np.array(cameras), np.array(directions), opt)
    single = np.array(
        [math.sqrt(_solve_from(kin, starts[i], cameras[i], directions[i], opt)[1]) for i in range(n)]
    )
    solved = single < 1e-5
    assert 0 < solved.sum() < n  # both kinds are tested
    np.testing.assert_array_equal(batched < 1e-5, solved)
    np.testing.assert_array_equal(batched <= _WORTH_SOLVING, single <= _WORTH_SOLVING)
    alike = np.isclose(batched[~solved], single[~solved], rtol=1e-6, atol=0.0)
    assert alike.mean() >= 0.95, f"{(~alike).sum()} of {alike.size} failing starts end elsewhere"


def test_look_at_ik_round_trip(arm):
    kin, _ = arm
    rng = np.random.default_rng(2)
    ok = 0
    n = 200
    for _ in range(n):
        q = kin.random_configuration(rng)
        p, R = kin.camera_pose(q)
        target = p + R[:, 0] * rng.uniform(0.2, 1.0)
        res = look_at_ik(kin, p, target, kin.home, rng)
        assert kin.within_limits(res.q)
        if res.success:
            ok += 1
            p2, R2 = kin.camera_pose(res.q)
            assert np.linalg.norm(p2 - p) <= 1e-4
            d = (target - p) / np.linalg.norm(target - p)
            assert math.acos(min(1.0, R2[:, 0] @ d)) <= 1e-3
    assert ok >= 0.99 * n


def test_ik_reports_failure_for_unreachable_targets():
    kin = ArmKinematics(get_robot("manipulator_h"), "emanual")
    res = look_at_ik(kin, np.array([2.0, 0.0, 0.5]), np.array([3.0, 0.0, 0.5]), kin.home)
    assert not res.success and res.position_error_m > 1.0
    assert kin.within_limits(res.q)


def test_arm_steps_one_second_from_home_without_warnings(arm):
    kin, am = arm
    data = mujoco.MjData(am.model)
    mujoco.mj_resetDataKeyframe(am.model, data, am.model.key("home").id)
    np.testing.assert_allclose(data.qpos[am.qpos_adr], kin.home)
    for _ in range(round(1.0 / am.model.opt.timestep)):
        mujoco.mj_step(am.model, data)
    assert sum(w.number for w in data.warning) == 0
    assert np.all(np.isfinite(data.qpos))
    assert np.abs(data.qpos[am.qpos_adr] - kin.home).max() < 0.05  # servos hold home


def test_actuators_carry_the_servo_limits():
    kin = ArmKinematics(get_robot("manipulator_h"), "emanual")
    m = compile_arm(kin).model
    np.testing.assert_allclose(m.actuator_forcerange[:, 1], [44.7, 44.7, 25.3, 25.3, 5.1, 5.1])
    np.testing.assert_allclose(m.jnt_range[:, 0], kin.limits.lower)
    np.testing.assert_allclose(m.jnt_range[:, 1], kin.limits.upper)
    # link1 (0.85644 kg) is static and fused into the world; the moving links weigh the rest
    moving = 0.94658 + 1.30260 + 1.15977 + 0.44688 + 0.43273 + 0.01919
    assert m.body_mass.sum() == pytest.approx(moving, abs=1e-9)


@pytest.mark.parametrize("limit_set", ["urdf", "emanual"])
def test_manipulator_h_reach(limit_set):
    """The farthest end_link point from (0, 0, 0.159) m over the limits is 0.648 m."""
    kin = ArmKinematics(get_robot("manipulator_h"), limit_set)
    fid = kin.model.getFrameId("end_link")
    centre = np.array([0.0, 0.0, 0.159])

    def neg_distance(q):
        pin.framesForwardKinematics(kin.model, kin.data, q)
        return -float(np.linalg.norm(kin.data.oMf[fid].translation - centre))

    rng = np.random.default_rng(3)
    bounds = list(zip(kin.limits.lower, kin.limits.upper, strict=True))
    best = max(
        -minimize(neg_distance, kin.random_configuration(rng), method="L-BFGS-B", bounds=bounds).fun
        for _ in range(30)
    )
    assert best == pytest.approx(0.648, abs=0.002)


def test_zero_pose_matches_the_published_joint_origins():
    kin = ArmKinematics(get_robot("manipulator_h"), "urdf")
    pin.framesForwardKinematics(kin.model, kin.data, np.zeros(6))
    expected = {
        "joint1": (0, 0, 0.126),
        "joint2": (0, 0.069, 0.159),
        "joint3": (0.03, 0.0575, 0.423),
        "joint4": (0.225, 0, 0.453),
        "joint5": (0.288, 0.045, 0.453),
        "joint6": (0.411, 0, 0.453),
    }
    for name, xyz in expected.items():
        np.testing.assert_allclose(kin.data.oMi[kin.model.getJointId(name)].translation, xyz, atol=1e-9)


def test_bad_robot_settings_are_named():
    with pytest.raises(ConfigError, match=r"robot\.name"):
        get_robot("kuka")
    with pytest.raises(ConfigError, match=r"robot\.joint_limits"):
        ArmKinematics(get_robot("ur5"), "emanual")


def test_image_roll_is_the_angle_from_the_worlds_up_about_the_optical_axis():
    from bve_mj.robot.ik import image_roll_rad

    for roll_deg in (0.0, 30.0, -75.0, 179.0):
        a = math.radians(roll_deg)
        # looking along world x, turned by `a` about it: left (y) = cos a ŷ + sin a ẑ
        R = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), -math.sin(a)], [0.0, math.sin(a), math.cos(a)]])
        tilt = pin.utils.rpyToMatrix(0.0, 0.4, 0.0)  # the axis 23° below the horizon: same roll
        assert image_roll_rad(tilt @ R) == pytest.approx(a, abs=1e-9)
    down = pin.utils.rpyToMatrix(0.0, math.pi / 2, 0.0)  # looking straight down: no up
    assert image_roll_rad(down) is None


def test_level_camera_turns_the_image_upright_holding_position_and_look_at(arm):
    """From mid-range configurations of every arm, the free roll is turned upright (most to
    within 5°), the camera's position and look-at held within the IK's tolerances, the joints
    within their limits, and never a turn for the worse."""
    from bve_mj.robot.ik import image_roll_rad, level_camera

    kin, _ = arm
    rng = np.random.default_rng(7)
    lo, hi = kin.limits.lower, kin.limits.upper
    before, after = [], []
    while len(before) < 40:
        q = lo + (hi - lo) * rng.uniform(0.25, 0.75, kin.nq)
        p, R = kin.camera_pose(q)
        roll = image_roll_rad(R)
        if roll is None:
            continue
        q_level = level_camera(kin, q, p + 0.3 * R[:, 0])
        p2, R2 = kin.camera_pose(q_level)
        assert kin.within_limits(q_level)
        assert np.linalg.norm(p2 - p) <= 1e-4
        assert math.acos(min(1.0, R2[:, 0] @ R[:, 0])) <= 1e-3
        roll2 = image_roll_rad(R2)
        assert roll2 is not None and abs(roll2) <= abs(roll) + 1e-9
        before.append(abs(roll))
        after.append(abs(roll2))
    assert np.median(before) > math.radians(30.0)  # the IK's free roll is arbitrary...
    assert np.mean(np.array(after) <= math.radians(5.0)) >= 0.65  # ...and mostly turned upright


def test_look_at_ik_upright_option(arm):
    from bve_mj.robot import IkOptions
    from bve_mj.robot.ik import image_roll_rad

    kin, _ = arm
    rng = np.random.default_rng(4)
    lo, hi = kin.limits.lower, kin.limits.upper
    rolls = {True: [], False: []}
    for _ in range(20):
        q = lo + (hi - lo) * rng.uniform(0.3, 0.7, kin.nq)
        p, R = kin.camera_pose(q)
        target = p + 0.3 * R[:, 0]
        for upright in (True, False):
            res = look_at_ik(kin, p, target, q, np.random.default_rng(0), IkOptions(upright=upright))
            assert res.success and res.position_error_m <= 1e-4 and res.axis_error_rad <= 1e-3
            rolls[upright].append(abs(image_roll_rad(kin.camera_pose(res.q)[1]) or 0.0))
    assert np.median(rolls[True]) < 0.5 * np.median(rolls[False])
