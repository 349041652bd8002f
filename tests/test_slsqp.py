"""The planner's SLSQP driver returns what scipy.optimize.minimize returns, bit for bit, having
called the objective and the constraints at the same points in the same order."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.optimize import minimize

from bve_mj.planning.slsqp import FAST_PATH, minimize_slsqp


class Logged:
    """A problem whose functions log every call (kind, point) to a shared list."""

    def __init__(self, log: list[tuple[str, tuple[float, ...]]], rng: np.random.Generator, n: int) -> None:
        self.log = log
        self.A = rng.normal(size=(n, n))
        self.b = rng.normal(size=n)
        self.c = rng.normal(size=n)

    def f(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        self.log.append(("f", tuple(x)))
        r = self.A @ x - self.b
        return float(r @ r + np.sum(np.sin(3 * x))), 2 * self.A.T @ r + 3 * np.cos(3 * x)

    def ineq(self, x: np.ndarray) -> np.ndarray:  # inside a ball and a half-space
        self.log.append(("ineq", tuple(x)))
        return np.array([1.5 - x @ x, self.c @ x + 0.3])

    def ineq_jac(self, x: np.ndarray) -> np.ndarray:
        self.log.append(("ineq_jac", tuple(x)))
        return np.array([-2 * x, self.c])

    def eq(self, x: np.ndarray) -> np.ndarray:
        self.log.append(("eq", tuple(x)))
        return np.array([x[0] - 0.5 * x[-1] ** 2])

    def eq_jac(self, x: np.ndarray) -> np.ndarray:
        self.log.append(("eq_jac", tuple(x)))
        J = np.zeros((1, x.size))
        J[0, 0], J[0, -1] = 1.0, -x[-1]
        return J


@pytest.mark.parametrize("case", range(24))
def test_matches_scipy_minimize(case: int) -> None:
    rng = np.random.default_rng(case)
    n = 3 + case % 5
    x0 = rng.normal(size=n)
    with_eq, with_bounds, with_ineq = case % 2 == 0, case % 3 != 0, case % 4 != 3
    bounds = [(-0.8, 0.9)] * (n - 1) + [(None, 0.7)] if with_bounds else None
    maxiter = 100 if case % 5 else 4  # some stop on the iteration cap
    ftol = 1e-10 if case % 2 else 1e-6

    log_ref: list[tuple[str, tuple[float, ...]]] = []
    ref = Logged(log_ref, np.random.default_rng(100 + case), n)
    cons = []
    if with_ineq:
        cons.append({"type": "ineq", "fun": ref.ineq, "jac": ref.ineq_jac})
    if with_eq:
        cons.append({"type": "eq", "fun": ref.eq, "jac": ref.eq_jac})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expected = minimize(
            ref.f, x0, jac=True, method="SLSQP", bounds=bounds, constraints=cons,
            options={"maxiter": maxiter, "ftol": ftol},
        )  # fmt: skip

    log: list[tuple[str, tuple[float, ...]]] = []
    ours = Logged(log, np.random.default_rng(100 + case), n)
    got = minimize_slsqp(
        ours.f, x0,
        ineq=[(ours.ineq, ours.ineq_jac)] if with_ineq else (),
        eq=[(ours.eq, ours.eq_jac)] if with_eq else (),
        bounds=bounds, maxiter=maxiter, ftol=ftol,
    )  # fmt: skip

    assert np.array_equal(got.x, expected.x)
    assert got.fun == expected.fun
    assert (got.nit, got.nfev, got.status, got.success) == (
        expected.nit, expected.nfev, expected.status, expected.success,
    )  # fmt: skip
    assert got.message == expected.message
    assert log == log_ref  # the same calls at the same points, in the same order


def test_fast_path_on_tested_scipy() -> None:
    """The driver is the one in use with the SciPy this project is tested with."""
    import scipy

    if scipy.__version__.startswith("1.17."):
        assert FAST_PATH


@pytest.mark.parametrize("case", range(12))
def test_lazy_gradient_gives_the_same_result(case: int) -> None:
    """With lazy=True the objective returns its gradient as a function, called only where
    SLSQP asks for the gradient: the same answer as minimize with jac=True, fewer gradients."""
    rng = np.random.default_rng(case)
    n = 3 + case % 4
    x0 = rng.normal(size=n)
    bounds = [(-0.8, 0.9)] * n if case % 2 else None
    problem = Logged([], np.random.default_rng(100 + case), n)
    cons = [{"type": "ineq", "fun": problem.ineq, "jac": problem.ineq_jac}]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expected = minimize(
            problem.f, x0, jac=True, method="SLSQP", bounds=bounds, constraints=cons,
            options={"maxiter": 100, "ftol": 1e-10},
        )  # fmt: skip
    gradients = []

    def lazy(x: np.ndarray):
        value, grad = problem.f(x)
        return value, lambda: gradients.append(1) or grad

    got = minimize_slsqp(
        lazy, x0, ineq=[(problem.ineq, problem.ineq_jac)], bounds=bounds, maxiter=100, ftol=1e-10, lazy=True
    )
    assert np.array_equal(got.x, expected.x) and got.fun == expected.fun
    assert (got.nit, got.nfev, got.status) == (expected.nit, expected.nfev, expected.status)
    assert len(gradients) == expected.njev


@pytest.mark.parametrize("lazy", [False, True])
def test_other_scipy_versions_call_minimize(monkeypatch: pytest.MonkeyPatch, lazy: bool) -> None:
    import bve_mj.planning.slsqp as driver

    problem = Logged([], np.random.default_rng(7), 4)
    x0 = np.full(4, 0.2)
    kwargs = {"ineq": [(problem.ineq, problem.ineq_jac)], "bounds": [(-1.0, 1.0)] * 4, "ftol": 1e-10}
    fast = driver.minimize_slsqp(problem.f, x0, **kwargs)  # type: ignore[arg-type]
    monkeypatch.setattr(driver, "FAST_PATH", False)
    fun = (lambda x: (problem.f(x)[0], lambda: problem.f(x)[1])) if lazy else problem.f
    slow = driver.minimize_slsqp(fun, x0, lazy=lazy, **kwargs)  # type: ignore[arg-type]
    assert np.array_equal(fast.x, slow.x) and fast.fun == slow.fun and fast.nit == slow.nit


@pytest.mark.parametrize("case", range(8))
def test_halt_stops_where_a_callback_raising_stop_iteration_stops_minimize(case: int) -> None:
    """``halt(x, f)`` is called after each major iteration with the iterate ``minimize`` passes
    its callback; True stops the run there, as a callback raising StopIteration stops
    ``minimize``: the same point, value, counts, status and calls."""
    rng = np.random.default_rng(case)
    n = 3 + case % 4
    x0 = rng.normal(size=n)
    bounds = [(-0.8, 0.9)] * n if case % 2 else None
    stop_after = 2 + case % 3
    seen_ref: list[tuple[tuple[float, ...], float]] = []

    def callback(intermediate_result) -> None:
        seen_ref.append((tuple(intermediate_result.x), float(intermediate_result.fun)))
        if len(seen_ref) >= stop_after:
            raise StopIteration

    log_ref: list[tuple[str, tuple[float, ...]]] = []
    ref = Logged(log_ref, np.random.default_rng(100 + case), n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expected = minimize(
            ref.f, x0, jac=True, method="SLSQP", bounds=bounds, callback=callback,
            constraints=[{"type": "ineq", "fun": ref.ineq, "jac": ref.ineq_jac}],
            options={"maxiter": 100, "ftol": 1e-10},
        )  # fmt: skip
    seen: list[tuple[tuple[float, ...], float]] = []

    def halt(x: np.ndarray, f: float) -> bool:
        seen.append((tuple(x), float(f)))
        return len(seen) >= stop_after

    log: list[tuple[str, tuple[float, ...]]] = []
    ours = Logged(log, np.random.default_rng(100 + case), n)
    got = minimize_slsqp(
        ours.f, x0, ineq=[(ours.ineq, ours.ineq_jac)], bounds=bounds, maxiter=100, ftol=1e-10, halt=halt
    )
    assert seen == seen_ref and len(seen) == stop_after
    assert np.array_equal(got.x, expected.x) and got.fun == expected.fun
    assert (got.nit, got.nfev, got.status, got.success) == (
        expected.nit, expected.nfev, expected.status, expected.success,
    )  # fmt: skip
    assert got.message == expected.message and log == log_ref


def test_other_scipy_versions_halt_where_the_driver_does(monkeypatch: pytest.MonkeyPatch) -> None:
    import bve_mj.planning.slsqp as driver

    problem = Logged([], np.random.default_rng(8), 4)
    x0 = np.full(4, 0.2)
    kwargs = {"ineq": [(problem.ineq, problem.ineq_jac)], "bounds": [(-1.0, 1.0)] * 4, "ftol": 1e-10}

    def after(k: int):
        calls: list[float] = []
        return lambda x, f: calls.append(f) or len(calls) >= k

    fast = driver.minimize_slsqp(problem.f, x0, halt=after(2), **kwargs)  # type: ignore[arg-type]
    monkeypatch.setattr(driver, "FAST_PATH", False)
    slow = driver.minimize_slsqp(problem.f, x0, halt=after(2), **kwargs)  # type: ignore[arg-type]
    assert np.array_equal(fast.x, slow.x) and (fast.nit, fast.status) == (slow.nit, slow.status) == (2, 99)
