"""SLSQP as ``scipy.optimize.minimize(method="SLSQP", jac=True)`` runs it, without its per-call
wrapping.

SciPy drives its C SLSQP routine from Python: each call of ``minimize`` validates and
standardises its arguments and wraps the objective in three memoising layers
(``MemoizeJac``, ``ScalarFunction``, a clipping wrapper) that compare and copy the point at
every evaluation. For the planner's small problems (3 to 8 variables, ~20 evaluations) that
wrapping costs as much as the objective itself. :func:`minimize_slsqp` drives the same C
routine with the same state, buffers and call sequence (objective, constraints and their
Jacobians evaluated at the same points, in the same order, as often), so it returns the
same ``x``, ``fun``, ``nit``, ``nfev`` and status bit for bit (``tests/test_slsqp.py``
checks it against ``minimize``).

The driver follows SciPy 1.17's ``scipy.optimize._slsqp_py._minimize_slsqp`` (the C routine
of SciPy >= 1.16, driven from Python); with any other SciPy (check another version with
``tests/test_slsqp.py`` before adding it to ``_TESTED``), :func:`minimize_slsqp` calls
``scipy.optimize.minimize`` itself.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy

__all__ = ["FAST_PATH", "SlsqpResult", "minimize_slsqp"]

Vector = Callable[[np.ndarray], Any]
ConstraintPair = tuple[Vector, Vector]  # (fun, jac): fun(x) (m,), jac(x) (m, n)

try:  # the C routine of SciPy >= 1.16
    from scipy.optimize._slsqplib import slsqp as _slsqp_c
except ImportError:  # pragma: no cover - other SciPy versions
    _slsqp_c = None

_TESTED = ((1, 17),)  # SciPy versions whose driver this one replays (tests/test_slsqp.py)
FAST_PATH: bool = _slsqp_c is not None and tuple(int(p) for p in scipy.__version__.split(".")[:2]) in _TESTED
"""Whether :func:`minimize_slsqp` drives SciPy's routine itself (else it calls ``minimize``)."""

_EXIT_MODES = {
    -1: "Gradient evaluation required (g & a)",
    0: "Optimization terminated successfully",
    1: "Function evaluation required (f & c)",
    2: "More equality constraints than independent variables",
    3: "More than 3*n iterations in LSQ subproblem",
    4: "Inequality constraints incompatible",
    5: "Singular matrix E in LSQ subproblem",
    6: "Singular matrix C in LSQ subproblem",
    7: "Rank-deficient equality constraint subproblem HFTI",
    8: "Positive directional derivative for linesearch",
    9: "Iteration limit reached",
    99: "`callback` raised `StopIteration`.",  # ``minimize``'s status where a callback halts it
}
_HALTED = 99


@dataclass(frozen=True)
class SlsqpResult:
    """What ``minimize`` returns for SLSQP (the fields the planners read)."""

    x: np.ndarray
    fun: float
    nit: int
    nfev: int
    status: int
    success: bool
    message: str


def minimize_slsqp(
    fun: Callable[[np.ndarray], tuple[Any, Any]],
    x0: np.ndarray,
    *,
    ineq: Sequence[ConstraintPair] = (),
    eq: Sequence[ConstraintPair] = (),
    bounds: Sequence[tuple[float | None, float | None]] | None = None,
    maxiter: int = 100,
    ftol: float = 1e-6,
    lazy: bool = False,
    halt: Callable[[np.ndarray, float], bool] | None = None,
) -> SlsqpResult:
    """``minimize(fun, x0, jac=True, method="SLSQP", bounds=bounds, constraints=[{"type":
    "ineq", "fun": f, "jac": j} for f, j in ineq] + [... "eq" ...], options={"maxiter":
    maxiter, "ftol": ftol})``: ``fun`` returns (value, gradient); constraints hold where
    their functions are ≥ 0 (``ineq``) or = 0 (``eq``).

    ``lazy``: ``fun`` returns (value, a function that computes the gradient), called only
    where SLSQP asks for the gradient (not at a line search's rejected trial points): the
    same result when it returns the same bits as the eager gradient.

    ``halt(x, f)``: called after each major iteration, as ``minimize`` calls a ``callback``;
    True stops the run there (``minimize``'s callback raising ``StopIteration``: the same
    result, status 99, not a success)."""
    if not FAST_PATH:
        if lazy:
            eager = fun

            def fun(p: np.ndarray) -> tuple[Any, Any]:
                value, gradient = eager(p)
                return value, gradient()

        return _with_scipy(fun, x0, ineq, eq, bounds, maxiter, ftol, halt)
    x = np.asarray(x0, dtype=float).reshape(-1).copy()
    n = x.size
    if bounds is None or len(bounds) == 0:
        x = np.clip(x, -np.inf, np.inf)
        xl = np.full(n, np.nan)
        xu = np.full(n, np.nan)
    else:
        lb = np.array([-np.inf if lo is None else float(lo) for lo, _ in bounds])
        ub = np.array([np.inf if hi is None else float(hi) for _, hi in bounds])
        if lb.shape != (n,):
            raise ValueError("The number of bounds is not compatible with the length of `x0`.")
        if np.any(ub < lb):
            raise ValueError("An upper bound is less than the corresponding lower bound.")
        if np.all(lb == ub):  # pragma: no cover - SciPy then evaluates at the bounds instead
            return _with_scipy(fun, x0, ineq, eq, bounds, maxiter, ftol, halt)
        x = np.clip(x, lb, ub)
        xl = np.where(np.isfinite(lb), lb, np.nan)
        xu = np.where(np.isfinite(ub), ub, np.nan)

    cons = [*eq, *ineq]
    meq = sum(len(np.atleast_1d(f(x))) for f, _ in eq)
    mieq = sum(len(np.atleast_1d(f(x))) for f, _ in ineq)
    m = meq + mieq

    # ScalarFunction and MemoizeJac: the objective is evaluated (value and gradient together)
    # whenever the point differs from the last one evaluated; nfev counts value requests
    # that found the value not yet requested at that point.
    last = x.tolist()  # a list of new floats: == compares as np.array_equal (nan != nan)
    value, grad = fun(x.copy())
    nfev = 1
    value_asked, grad_asked = True, True

    def at(p: np.ndarray) -> None:
        nonlocal last, value, grad, value_asked, grad_asked
        key = p.tolist()
        if key != last:
            last = key
            value, grad = fun(p.copy())
            value_asked = grad_asked = False

    def gradient() -> np.ndarray:
        return np.atleast_1d(grad() if lazy else grad)

    def scalar(v: Any) -> Any:
        return v if np.isscalar(v) else np.asarray(v).item()

    fx = scalar(value)
    g = gradient()

    buffer_size = n * (n + 1) // 2 + 3 * m * n - (m + 5 * n + 7) * meq + 9 * m + 8 * n * n + 35 * n
    buffer_size += meq * meq + 28
    if mieq == 0:
        buffer_size += 2 * n * (n + 1)
    state: dict[str, Any] = {
        "acc": ftol, "alpha": 0.0, "f0": 0.0, "gs": 0.0, "h1": 0.0, "h2": 0.0, "h3": 0.0,
        "h4": 0.0, "t": 0.0, "t0": 0.0, "tol": 10.0 * ftol, "exact": 0, "inconsistent": 0,
        "reset": 0, "iter": 0, "itermax": int(maxiter), "line": 0, "m": m, "meq": meq,
        "mode": 0, "n": n,
    }  # fmt: skip
    indices = np.zeros([max(m + 2 * n + 2, 1)], dtype=np.int32)
    buffer = np.zeros(max(buffer_size, 1), dtype=np.float64)
    mult = np.zeros([max(1, m + 2 * n + 2)], dtype=np.float64)
    C = np.zeros([max(1, m), n], dtype=np.float64, order="F")
    d = np.zeros([max(1, m)], dtype=np.float64)

    def normals() -> None:
        row = 0
        for _, jac in cons:
            rows = np.atleast_2d(jac(x))
            C[row : row + rows.shape[0], :] = rows
            row += rows.shape[0]

    def values() -> None:
        row = 0
        for f, _ in cons:
            v = np.atleast_1d(f(x)).ravel()
            d[row : row + len(v)] = v
            row += len(v)

    if m:
        normals()
        values()
    iter_prev = 0
    while True:
        _slsqp_c(state, fx, g, C, d, x, mult, xl, xu, buffer, indices)
        mode = state["mode"]
        if mode == 1:
            at(x)
            if not value_asked:
                fx = scalar(value)
                nfev += 1
                value_asked = True
            if m:
                values()
        if mode == -1:
            at(x)
            if not grad_asked:
                g = gradient()
                grad_asked = True
            if m:
                normals()
        if halt is not None and state["iter"] > iter_prev and halt(np.copy(x), fx):
            return SlsqpResult(x, fx, state["iter"], nfev, _HALTED, False, _EXIT_MODES[_HALTED])
        if abs(mode) != 1:
            break
        iter_prev = state["iter"]
    mode = state["mode"]
    return SlsqpResult(x, fx, state["iter"], nfev, mode, mode == 0, _EXIT_MODES[mode])


def _with_scipy(
    fun: Callable[[np.ndarray], tuple[float, np.ndarray]],
    x0: np.ndarray,
    ineq: Sequence[ConstraintPair],
    eq: Sequence[ConstraintPair],
    bounds: Sequence[tuple[float | None, float | None]] | None,
    maxiter: int,
    ftol: float,
    halt: Callable[[np.ndarray, float], bool] | None = None,
) -> SlsqpResult:
    from scipy.optimize import OptimizeResult, minimize

    constraints = [{"type": "ineq", "fun": f, "jac": j} for f, j in ineq]
    constraints += [{"type": "eq", "fun": f, "jac": j} for f, j in eq]

    def callback(intermediate_result: OptimizeResult) -> None:
        if halt is not None and halt(intermediate_result.x, intermediate_result.fun):
            raise StopIteration

    res = minimize(
        fun, x0, jac=True, method="SLSQP", bounds=bounds, constraints=constraints,
        options={"maxiter": maxiter, "ftol": ftol}, callback=None if halt is None else callback,
    )  # fmt: skip
    return SlsqpResult(
        np.asarray(res.x), res.fun, int(res.nit), int(res.nfev), int(res.status), bool(res.success),
        str(res.message),
    )  # fmt: skip
