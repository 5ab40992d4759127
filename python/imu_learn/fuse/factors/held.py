"""Levenberg-Marquardt over a graph with Python factors (``gtsam.CustomFactor``: :mod:`.nhc`,
:mod:`.displacement`) at the cost of a native graph.

Why: GTSAM's Python wrapper hands each ``CustomFactor`` call the optimiser's ``Values`` by copy
whenever that ``Values`` lives in C++ (inside ``LevenbergMarquardtOptimizer``), so every call costs
a copy of every variable of the graph: in the batch pass over the car drive (6,635 keyframes,
~20,000 variables, 6,635 NHC factors) milliseconds per call, nearly all of the drive's 650 s against
14 s without NHC on a loaded machine (docs/experiments/benchmarks.md, 20 s now). Called from Python with a Python-held ``Values`` the same
factor costs tens of microseconds (no copy).

How: each Python factor is linearised here (Python-held values: no copy) and held as GTSAM's
``LinearContainerFactor`` at that linearisation point (native: its error and Jacobian follow the
variables' tangent-space offset from that point to first order); Levenberg-Marquardt runs on that
native graph; the Python factors are relinearised at its solution and LM runs again, until the
true (nonlinear) error stops decreasing by more than LM's own convergence tests. At the end point
the held factors' error and Jacobian are the Python factors' own, so it is a stationary point of
the true problem (the Gauss-Newton fixed point), the one LM on the true graph converges to; a step
that raises the true error falls back to LM on the true graph from there.
"""
from __future__ import annotations

from typing import Any, List

#: Relinearisations at most (the car drive settles in 2 LM runs).
MAX_RELINEARISATIONS = 10


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


def optimize(graph: Any, initial: Any, params: Any) -> Any:
    """Levenberg-Marquardt (``params``) over ``graph`` from ``initial``: the optimum ``Values``, with
    its Python factors held at a relinearised point (module docstring); plain LM when it has none."""
    import gtsam

    slots = python_factor_slots(graph)
    if not slots:
        return gtsam.LevenbergMarquardtOptimizer(graph, initial, params).optimize()
    est, err = initial, graph.error(initial)
    for _ in range(MAX_RELINEARISATIONS):
        new = gtsam.LevenbergMarquardtOptimizer(held_graph(graph, slots, est), est, params).optimize()
        new_err = graph.error(new)
        if settled(params, err, new_err):
            return new if new_err < err else est
        if new_err > err:  # the held linearisation misled LM: the true graph from the last good point
            return gtsam.LevenbergMarquardtOptimizer(graph, est, params).optimize()
        est, err = new, new_err
    return est


def settled(params: Any, err: float, new_err: float) -> bool:
    """LM's convergence tests (``params``' relative and absolute error tolerances) on a change of the
    true error from ``err`` to ``new_err``, either way."""
    change = abs(err - new_err)
    return change <= params.getAbsoluteErrorTol() or change <= params.getRelativeErrorTol() * err \
        or new_err <= params.getErrorTol()
