"""Arguments the Rust core is given from Python are checked before anything is sized or indexed by
them: a huge, negative or zero horizon, starts past the end, a huge batch are typed errors naming
the argument, never a pyo3 PanicException or an abort. Each case runs in a child
process too, so an abort (which would kill pytest itself) shows up as a failure, not a crash."""
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import imu_learn as il
import imu_learn.errors as errors
from imu_learn import _imu_core as core
from imu_learn.core import covariance as cov
from imu_learn.core import integration

N = 10
T = np.arange(N, dtype=np.int64) * 5_000_000
G = np.tile([0.1, -0.2, 0.3], (N, 1))
A = np.tile([0.0, 0.0, 9.81], (N, 1))
SEQ = il.Segment("s", T, G, A, np.zeros((N, 3)), np.zeros((N, 3)), np.tile([1.0, 0, 0, 0], (N, 1)))
HUGE = 2**40

# (starts, horizons, words the message must hold): N = 10 samples allow horizons 1..9.
BAD_WINDOWS = {
    "empty starts, horizon 2^40": ([], [HUGE], [f"horizons[0] = {HUGE}", "past the sequence end", "1..=9"]),
    "empty starts, horizon 2^64-1": (np.array([], np.uint64), np.array([2**64 - 1], np.uint64), ["horizons[0]"]),
    "negative horizon": ([0], [-1], ["horizons[0] = -1", "non-negative"]),
    "empty starts, negative horizon": ([], [3, -5], ["horizons[1] = -5"]),
    "horizon 0": ([0], [0], ["horizons[0] = 0", "at least 1"]),
    "horizon = length": ([0], [N], [f"horizons[0] = {N}", "past the sequence end"]),
    "start past the end": ([0, N], [1], [f"starts[1]: window start {N} + horizon 1", "past the sequence end"]),
    "start + horizon past the end": ([0, 5], [5], ["starts[1]: window start 5 + horizon 5"]),
    "negative start": ([-1], [1], ["starts[0] = -1"]),
    "start 2^63": (np.array([2**63], np.uint64), np.array([1], np.uint64), ["starts[0]"]),
}


def _raw(starts, horizons):
    """The arrays as a direct caller of _imu_core passes them: int64 for signed input."""
    def arr(x):
        a = np.asarray(x)
        return a if a.dtype.kind in "iu" and a.size else np.asarray(x, dtype=np.int64)
    return arr(starts), arr(horizons)


@pytest.mark.parametrize("case", list(BAD_WINDOWS))
def test_integrate_windows_rejects_bad_windows_through_the_wrapper(case):
    starts, horizons, words = BAD_WINDOWS[case]
    with pytest.raises(errors.InvalidInputError) as e:
        integration.integrate_windows(SEQ, starts, horizons)
    assert type(e.value) is errors.InvalidInputError
    for w in words:
        assert w in str(e.value), (case, str(e.value))


@pytest.mark.parametrize("case", list(BAD_WINDOWS))
def test_integrate_windows_rejects_bad_windows_in_the_core_directly(case):
    starts, horizons, words = BAD_WINDOWS[case]
    for s, h in [_raw(starts, horizons), (list(np.asarray(starts).tolist()), list(np.asarray(horizons).tolist()))]:
        with pytest.raises(errors.InvalidInputError) as e:
            core.integrate_windows(T, G, A, s, h)
        for w in words:
            assert w in str(e.value), (case, str(e.value))


def test_empty_starts_give_an_empty_result_and_good_windows_still_work():
    out = integration.integrate_windows(SEQ, [], [1, 9])
    assert out.dq_wxyz.shape == (0, 2, 4) and out.dt.shape == (0, 2)
    assert list(out.horizons) == [1, 9]
    ok = integration.integrate_windows(SEQ, np.array([0, 1], np.int64), np.array([8, 1], np.int64))
    assert ok.dt.shape == (2, 2)
    assert ok.dt[0, 0] == pytest.approx(8 * 0.005) and ok.dt[1, 1] == pytest.approx(0.005)
    # Signed and unsigned index arrays and lists give the same result.
    u = core.integrate_windows(T, G, A, np.array([0, 1], np.uint64), np.array([8, 1], np.uint64))
    lst = core.integrate_windows(T, G, A, [0, 1], [8, 1])
    for k in ("dq_wxyz", "dv", "dp", "dt"):
        np.testing.assert_array_equal(u[k], getattr(ok, k))
        np.testing.assert_array_equal(lst[k], getattr(ok, k))


def test_non_integer_or_2d_indices_are_typed_errors():
    with pytest.raises(errors.InvalidInputError, match="horizons must be a 1-d sequence of integers"):
        integration.integrate_windows(SEQ, [0], [1.5])
    with pytest.raises(errors.InvalidInputError, match="starts must be a 1-d sequence of integers"):
        integration.integrate_windows(SEQ, [[0]], [1])
    # The core alone: pyo3 refuses to convert, naming the argument (a TypeError, not a panic).
    with pytest.raises(TypeError, match="horizons"):
        core.integrate_windows(T, G, A, [0], np.array([1.5]))


VAR = np.full((N, 6), 1e-4)


@pytest.mark.parametrize("fn,name", [(core.increment_covariance, "horizons"), (core.interval_covariances, "boundaries")])
@pytest.mark.parametrize("idx,word", [([HUGE], str(HUGE)), (np.array([-1], np.int64), "= -1"), ([-3], "= -3"),
                                      (np.array([2**64 - 1], np.uint64), str(2**64 - 1))])
def test_covariance_indices_are_checked_in_the_core(fn, name, idx, word):
    with pytest.raises(errors.InvalidInputError) as e:
        fn(T, G, A, VAR, idx)
    assert word in str(e.value)


def test_covariance_wrappers_name_the_argument():
    with pytest.raises(errors.InvalidInputError, match="horizons"):
        cov.increment_covariance(T, G, A, VAR, [-1])
    with pytest.raises(errors.InvalidInputError, match="horizon 1099511627776"):
        cov.increment_covariance(T, G, A, VAR, [HUGE])
    with pytest.raises(errors.InvalidInputError, match="boundary 1099511627776"):
        cov.interval_covariances(T, G, A, VAR, [0, HUGE])


def _sequence_set():
    return core.SequenceSet([(SEQ.t_ns, SEQ.gyro, SEQ.acc, SEQ.p, SEQ.v, SEQ.q_wxyz)])


@pytest.mark.parametrize("batch_size", [2**40, 2**62, 2**64 - 1])
def test_huge_batch_is_a_typed_error_not_an_abort(batch_size):
    with pytest.raises((errors.InvalidInputError, MemoryError)) as e:
        _sequence_set().make_batch(4, batch_size, [0.5, 1.0], 9.81, 0)
    if isinstance(e.value, errors.InvalidInputError):
        assert "batch_size" in str(e.value)


def test_huge_window_is_a_typed_error():
    s = _sequence_set()
    for window in (HUGE, 2**64 - 1):
        with pytest.raises(errors.InvalidInputError, match="needs"):
            s.make_batch(window, 2, [1.0], 9.81, 0)
        with pytest.raises(errors.InvalidInputError):
            s.eval_windows(window, 1, [1.0], 9.81)
    # window_labels: a sequence shorter than the window has no windows (empty, not an error).
    lab = core.window_labels(T, SEQ.p, SEQ.v, SEQ.q_wxyz, HUGE, 1, [1.0], 9.81)
    assert lab["dt"].shape == (0, 1) and list(lab["horizons"]) == [HUGE]


def test_huge_half_window_derives_velocity():
    p = np.stack([T * 1e-9, np.zeros(N), np.zeros(N)], axis=1)
    v = core.derive_velocity(T, p, 2**64 - 1)
    np.testing.assert_allclose(v[:, 0], 1.0, atol=1e-9)


def test_core_raises_the_classes_of_errors_py_itself():
    """import_exception!: the very classes of imu_learn.errors, not look-alikes or re-wraps."""
    with pytest.raises(errors.InvalidInputError) as e:
        core.preintegrate(np.arange(3, dtype=np.int64), np.zeros((3, 3)), np.zeros((2, 3)))
    assert type(e.value) is errors.InvalidInputError is il.InvalidInputError
    assert isinstance(e.value, ValueError) and isinstance(e.value, errors.ImuError)
    t = np.arange(20, dtype=np.int64) * 5_000_000
    z = np.zeros((20, 3))
    q = np.tile([1.0, 0, 0, 0], (20, 1))
    with pytest.raises(errors.NoOverlapError) as e:
        core.align(t, z, z, t + 10**12, z, q, None, 10**9, 2, 4, "imu.csv", "gt.csv")
    assert type(e.value) is errors.NoOverlapError
    assert (e.value.path, e.value.imu_path) == ("gt.csv", "imu.csv")


CHILD = textwrap.dedent("""
    import numpy as np, sys
    from imu_learn import _imu_core as core
    import imu_learn.errors as errors
    t = np.arange(10, dtype=np.int64) * 5_000_000; z = np.zeros((10, 3))
    cases = [([], [2**40]), (np.array([], np.int64), np.array([-1], np.int64)),
             (np.array([], np.uint64), np.array([2**64 - 1], np.uint64)), ([0], [0]), ([10], [1])]
    for s, h in cases:
        try:
            core.integrate_windows(t, z, z, s, h)
        except errors.InvalidInputError:
            continue
        sys.exit("no error for %r" % ((s, h),))
    print("all typed")
""")


def test_no_case_aborts_the_process():
    """An allocation of 2^40 entries aborts the process rather than raising: run the cases in a
    child so that this shows up as a failed test with the child's exit status."""
    r = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "all typed" in r.stdout, (r.returncode, r.stdout, r.stderr[-2000:])
    assert "PanicException" not in r.stderr


LIMITED = """
import resource, sys
import numpy as np
resource.setrlimit(resource.RLIMIT_AS, (3 * 2**30, 3 * 2**30))
from imu_learn import _imu_core as core, errors
n = 2000
t = (np.arange(n) * 5_000_000).astype(np.int64)
g, a, p, v = (np.zeros((n, 3)) for _ in range(4))
q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
calls = {"integrate_windows": lambda: core.integrate_windows(t, g, a, np.zeros(10**5, np.int64), np.ones(10**4, np.int64)),
         "window_labels": lambda: core.window_labels(t, p, v, q, 200, 1, [0.001] * 10**6, 9.81)}
try:
    calls[sys.argv[1]]()
    print("no error")
except (errors.InvalidInputError, MemoryError) as e:
    print("typed", type(e).__name__)
"""


@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_AS bounds the address space on Linux")
@pytest.mark.parametrize("call", ["integrate_windows", "window_labels"])
def test_windows_times_horizons_past_memory_is_an_error_not_an_abort(call):
    """A request whose outputs cannot be allocated (here under a 3 GiB address-space limit): a typed
    error or MemoryError, not the abort (SIGABRT) or PanicException it was."""
    r = subprocess.run([sys.executable, "-c", LIMITED, call], capture_output=True, text=True, timeout=120,
                       env={**os.environ, "RAYON_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})
    assert r.returncode == 0 and r.stdout.startswith("typed"), (r.returncode, r.stdout, r.stderr[-500:])


def test_window_labels_refuse_ground_truth_that_gave_nan_or_garbage_labels():
    """NaN in p, v or q, a zero quaternion, a non-finite gravity and stamps that do not increase gave
    NaN (or finite, wrong) labels without a word; each is an InvalidInputError naming what."""
    n = 600
    t = (np.arange(n) * 5_000_000).astype(np.int64)
    p, v = np.zeros((n, 3)), np.zeros((n, 3))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    core.window_labels(t, p, v, q, 200, 10, [1.0], 9.81)  # the good case runs
    cases = []
    for name, arr in (("p", p), ("v", v), ("q_wxyz", q)):
        bad = arr.copy()
        bad[250, 0] = np.nan
        cases.append(({name: bad}, rf"{name}\[250\]"))
    zero_q = q.copy()
    zero_q[300] = 0.0
    cases.append(({"q_wxyz": zero_q}, r"q_wxyz\[300\].*not a rotation"))
    cases.append(({"t_ns": np.zeros(n, dtype=np.int64)}, r"t_ns\[1\]"))
    cases.append(({"t_ns": t[::-1].copy()}, r"t_ns\[1\]"))
    cases.append(({"gravity": float("nan")}, "gravity"))
    for change, says in cases:
        args = {"t_ns": t, "p": p, "v": v, "q_wxyz": q, "gravity": 9.81, **change}
        with pytest.raises(errors.InvalidInputError, match=says):
            core.window_labels(args["t_ns"], args["p"], args["v"], args["q_wxyz"], 200, 10, [1.0], args["gravity"])


def test_a_sequence_set_refuses_a_nan_sample_it_would_put_in_batches():
    n = 600
    t = (np.arange(n) * 5_000_000).astype(np.int64)
    g, a, p, v = (np.zeros((n, 3)) for _ in range(4))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    core.SequenceSet([(t, g, a, p, v, q)])
    g[123, 2] = np.nan
    with pytest.raises(errors.InvalidInputError, match=r"sequence 0: gyro\[123\]"):
        core.SequenceSet([(t, g, a, p, v, q)])


def test_derive_velocity_refuses_stamps_and_positions_it_would_fit_wrongly():
    p = np.stack([T * 1e-9, np.zeros(N), np.zeros(N)], axis=1)
    np.testing.assert_allclose(core.derive_velocity(T, p, 5)[:, 0], 1.0, atol=1e-9)
    for t, q, hw, says in ((np.zeros(N, dtype=np.int64), p, 5, r"t_ns\[1\]"), (T[::-1].copy(), p, 5, r"t_ns\[1\]"),
                           (T, p, 0, "half_window = 0"), (T, np.where(np.arange(N)[:, None] == 3, np.nan, p), 5, r"p\[3\]")):
        with pytest.raises(errors.InvalidInputError, match=says):
            core.derive_velocity(t, q, hw)


@pytest.mark.parametrize("window, stride", [(200, -1), (200, 0), (-5, 10)])
def test_public_window_labels_name_a_window_or_stride_below_one(window, stride):
    seg = il.load_sequence(Path(__file__).resolve().parents[1] / "datasets" / "euroc" / "V1_01_easy")[0]
    with pytest.raises(errors.InvalidInputError, match="must be at least 1 sample"):
        il.window_labels(seg, window, stride)
