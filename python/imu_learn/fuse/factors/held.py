"""Levenberg-Marquardt over a graph with Python factors (``gtsam.CustomFactor``: :mod:`.nhc`,
:mod:`.displacement`) at the cost of a native graph.

Why: GTSAM's Python wrapper hands each ``CustomFactor`` call the optimiser's ``Values`` by copy
whenever that ``Values`` lives in C++ (inside ``LevenbergMarquardtOptimizer``), so every call costs
a copy of every variable of the graph: in the batch pass over the car drive (6,635 keyframes,
~20,000 variables, 6,635 NHC factors) milliseconds per call, nearly all of the drive's 650 s against
14 s without NHC on a loaded machine (docs/experiments/benchmarks.md, 20 s now). Called from Python with a Python-held ``Values`` the same
factor costs tens of microseconds (no copy).

How: at every Levenberg-Marquardt iteration each Python factor is linearised here (Python-held
values: no copy) and held as GTSAM's ``LinearContainerFactor`` at that point (native: its error and
Jacobian follow the variables' tangent-space offset from that point to first order); one LM iteration
runs on that native graph (its damping carried from one iteration to the next, as in one LM run),
and the true (nonlinear) error decides, with LM's own convergence tests, when to stop. At each
iteration's point the held factors' error and Jacobian are the Python factors' own, so the end point
is a stationary point of the true problem, the one LM on the true graph converges to. (Holding them
over a whole LM run instead, then relinearising and running LM again, took 2-3 runs of up to 4
iterations: 1.6-3.3x the pass without NHC on the 400 s stand-in of docs/experiments/navigate-nhc.md;
relinearised at every iteration, 1.4-2.3x.)

A step that raises the true error (the held linearisation misled LM: a start far from the optimum)
is shortened along the same tangent-space step (halved up to :data:`MAX_HALVINGS` times, each tried on
the true error, evaluated from Python: no copy); the held factors agree with the true ones to first
order at the step's origin, so a short enough step lowers the true error unless that origin is already
stationary. Only when no shortened step helps does it fall back to LM on the true graph (the costly
path above; before, any step that raised the true error went there).

``progress``: called once per LM iteration (``progress(true_error_or_None)``), for a progress bar.
"""
from __future__ import annotations

from typing import Any, Callable, List, Optional

#: Halvings of a step that raised the true error before LM on the true graph takes over.
MAX_HALVINGS = 8


def python_factor_slots(graph: Any) -> List[int]:
    """The slots of ``graph``'s ``gtsam.CustomFactor`` s."""
    import gtsam

    return [i for i in range(graph.size()) if isinstance(graph.at(i), gtsam.CustomFactor)]


def held_graph(graph: Any, slots: List[int], values: Any) -> Any:
    """``graph`` with the factors at ``slots`` linearised at ``values`` and held there
    (``LinearContainerFactor``); the others as they are (shared, not copied)."""
    import gtsam

    held = set(slots)
    out = gtsam.NonlinearFactorGraph()
    for i in range(graph.size()):
        f = graph.at(i)
        if f is None:
            continue
        out.add(gtsam.LinearContainerFactor(f.linearize(values), values) if i in held else f)
    return out


def optimize(graph: Any, initial: Any, params: Any, progress: Optional[Callable] = None) -> Any:
    """Levenberg-Marquardt (``params``) over ``graph`` from ``initial``: the optimum ``Values``, its
    Python factors held at the current estimate and relinearised at every iteration (module
    docstring); plain LM when it has none."""
    slots = python_factor_slots(graph)
    if not slots:
        return levenberg_marquardt(graph, initial, params, progress)
    est, err = initial, graph.error(initial)
    lam0 = params.getlambdaInitial()
    try:
        for _ in range(params.getMaxIterations()):
            new = lm_iteration(held_graph(graph, slots, est), est, params)
            new_err = graph.error(new)
            if new_err > err:  # the held linearisation misled LM: a shorter step along it
                new, new_err = shortened(graph, est, err, new)
                if new is None:
                    params.setlambdaInitial(lam0)
                    return levenberg_marquardt(graph, est, params, progress)
            if progress is not None:
                progress(new_err)
            if settled(params, err, new_err):
                return new if new_err < err else est
            est, err = new, new_err
        return est
    finally:
        params.setlambdaInitial(lam0)


def lm_iteration(graph: Any, values: Any, params: Any) -> Any:
    """One Levenberg-Marquardt iteration over ``graph`` from ``values`` (GTSAM's: the damping raised
    until a step lowers ``graph``'s error); the damping it ends with is left in ``params`` as the next
    iteration's start, as within one LM run."""
    import gtsam

    opt = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    opt.iterate()
    params.setlambdaInitial(max(opt.lambda_(), params.getlambdaLowerBound()))
    return opt.values()


def shortened(graph: Any, est: Any, err: float, new: Any) -> tuple:
    """The first of the steps from ``est`` towards ``new`` (tangent space) halved 1, 2, ...
    :data:`MAX_HALVINGS` times that lowers ``graph``'s true error below ``err``: ``(values, error)``,
    or ``(None, err)`` when none does."""
    step = est.localCoordinates(new)
    for h in range(1, MAX_HALVINGS + 1):
        cand = est.retract(step.scale(0.5 ** h))
        e = graph.error(cand)
        if e < err:
            return cand, e
    return None, err


def levenberg_marquardt(graph: Any, initial: Any, params: Any, progress: Optional[Callable] = None) -> Any:
    """GTSAM's Levenberg-Marquardt with ``params`` (its own loop and stopping tests: ``optimize()``);
    with ``progress``, the same loop run an iteration at a time here, ``progress(None)`` after each."""
    import gtsam

    opt = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
    if progress is None:
        return opt.optimize()
    err = opt.error()
    if err <= params.getErrorTol():
        return opt.values()
    while True:
        opt.iterate()
        new = opt.error()
        progress(None)
        if opt.iterations() >= params.getMaxIterations() or not new < float("inf") or gtsam.checkConvergence(
                params.getRelativeErrorTol(), params.getAbsoluteErrorTol(), params.getErrorTol(), err, new):
            return opt.values()
        err = new


def settled(params: Any, err: float, new_err: float) -> bool:
    """LM's convergence tests (``params``' relative and absolute error tolerances) on a change of the
    true error from ``err`` to ``new_err``, either way."""
    change = abs(err - new_err)
    return change <= params.getAbsoluteErrorTol() or change <= params.getRelativeErrorTol() * err \
        or new_err <= params.getErrorTol()
