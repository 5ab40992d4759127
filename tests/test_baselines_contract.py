"""What every method in the baselines registry (imu_learn.baselines.registry.REGISTRY) must do, one
test per promise, parametrised over the registry: a method registered tomorrow is held to all of them
without a line here (with its default configuration, unless TINY names a smaller one).

Each method is fitted once per module on 15 s of the shipped MH_01_easy crop (5 s validation) with a
tiny budget; the promises are about behaviour (shapes, finiteness, persistence, determinism, the
rotation_only flag), not accuracy: each method's own tests (test_baseline_<method>.py) hold its
numerical oracles and closed forms."""
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from crops import cut  # noqa: E402
from imu_learn.baselines.airimu_style import AirImuConfig  # noqa: E402
from imu_learn.baselines.base import FitSettings, Method, poses_from_imu  # noqa: E402
from imu_learn.baselines.end_to_end import EndToEndConfig  # noqa: E402
from imu_learn.baselines.proposed import ProposedConfig  # noqa: E402
from imu_learn.baselines.registry import REGISTRY, load_method_class, safe_name  # noqa: E402
from imu_learn.baselines.tlio import TlioConfig  # noqa: E402
from imu_learn.eval.run import is_refiner, save_method  # noqa: E402
from imu_learn.nn.model import ModelConfig  # noqa: E402

torch.set_num_threads(1)

METHODS = list(REGISTRY)
W = 50  # training window [samples] (0.25 s at 200 Hz)
SETTINGS = FitSettings(window=W, batch_size=8, steps=8, lr=3e-3, seed=0, threads=1)
STARTS = np.arange(0, 600, 37, dtype=np.uint64)  # window starts in the 1000-sample validation crop
HORIZONS = (10, W, 3 * W + 7)  # shorter than, equal to and longer than the training window

# A small instance of each method (the factory gets the registered class); unnamed: its defaults.
TINY = {
    "traditional": lambda cls: cls(cutoffs_hz=(None, 20.0), max_windows=60),
    "gyro-denoise": lambda cls: cls(channels=(8, 16), dilations=(1, 4), scales=(16, 32)),
    "end-to-end": lambda cls: cls(EndToEndConfig(hidden=8, layers=1, fc=8, evals=2)),
    "airimu-style": lambda cls: cls(AirImuConfig(conv=8, hidden=8, evals=2)),
    "proposed": lambda cls: cls(ProposedConfig(model=ModelConfig(hidden=8, layers=1, fc=8), evals=2)),
    "tlio-style": lambda cls: cls(TlioConfig(window_s=W / 200, width=8, fc=8, evals=2)),
}


def factory(name: str):
    cls = load_method_class(name)
    if cls is None:
        pytest.skip(f"{name}: its module is not importable here")
    return cls


def make(name: str) -> Method:
    return TINY.get(name, lambda cls: cls())(factory(name))


def learns(method: Method) -> bool:
    return type(method).fit is not Method.fit


def suffix(name: str, method: Method) -> str:
    """The file suffix evaluate saves ``name`` under (eval.run.prepare_method)."""
    return getattr(method, "save_suffix", None) or (".json" if name == "traditional" else ".pt")


def outputs(method: Method, seq):
    """Everything a method hands evaluation: refined samples and poses at each horizon."""
    g, a = method.refine(seq)
    return [g, a] + [x for n in HORIZONS for x in vars(method.predict(seq, STARTS, n)).values()]


def assert_same(xs, ys):
    assert len(xs) == len(ys)
    for i, (x, y) in enumerate(zip(xs, ys)):
        assert (x is None) == (y is None), f"output {i}: one side None"
        if x is not None:
            np.testing.assert_array_equal(x, y, err_msg=f"output {i}")


@pytest.fixture(scope="module", params=METHODS)
def name(request) -> str:
    return request.param


@pytest.fixture(scope="module")
def fitted(name, crop_split):
    """(method, its fit log), fitted on the 15 s train crop with the 5 s validation crop."""
    train, val = crop_split
    m = make(name)
    log = m.fit([train], [val], SETTINGS)
    return m, log


@pytest.fixture(scope="module")
def val(crop_split):
    return crop_split[1]


def test_registered_under_its_own_name(name):
    m = factory(name)()
    assert isinstance(m, Method)
    assert m.name == name  # evaluate's tables, records and fusion inputs all key on it
    assert safe_name(name) == name  # the saved file is <name><suffix>, nothing mangled
    assert isinstance(m.rotation_only, bool)


def test_fit_returns_a_log_of_finite_numbers(fitted):
    m, log = fitted
    assert isinstance(log, dict) and all(isinstance(k, str) and isinstance(v, list) for k, v in log.items())
    if learns(m):
        tl = log["train_loss"]
        assert len(tl) > 0 and np.isfinite(np.asarray(tl, dtype=np.float64)).all()
    for k, v in log.items():
        nums = [x for x in v if isinstance(x, float)]
        assert np.isfinite(nums).all(), k


def test_refine_gives_finite_float64_samples_of_the_input_shape(fitted, val):
    m, _ = fitted
    g, a = m.refine(val)
    for x, raw in ((g, val.gyro), (a, val.acc)):
        assert x.shape == raw.shape == (len(val), 3) and x.dtype == np.float64
        assert np.isfinite(x).all()


def test_refine_of_a_sequence_shorter_than_the_window(fitted, val):
    m, _ = fitted
    short = cut(val, 0, W - 7)
    g, a = m.refine(short)
    assert g.shape == a.shape == (W - 7, 3) and np.isfinite(g).all() and np.isfinite(a).all()


@pytest.mark.parametrize("n", HORIZONS)
def test_predict_gives_one_finite_pose_per_start(fitted, val, n):
    m, _ = fitted
    p = m.predict(val, STARTS, n)
    S = len(STARTS)
    assert p.q_wxyz.shape == (S, 4) and np.isfinite(p.q_wxyz).all()
    np.testing.assert_allclose(np.linalg.norm(p.q_wxyz, axis=1), 1.0, atol=1e-9)
    for x in (p.p, p.v):
        assert x is None or (x.shape == (S, 3) and np.isfinite(x).all())


def test_rotation_only_flag_is_honoured(fitted, val):
    """A rotation-only method predicts no position and no velocity; any other method a position."""
    m, _ = fitted
    p = m.predict(val, STARTS, W)
    if m.rotation_only:
        assert p.p is None and p.v is None
    else:
        assert p.p is not None


def test_a_refiners_poses_integrate_its_refined_samples(fitted, val):
    m, _ = fitted
    if not is_refiner(m):
        pytest.skip(f"{m.name} regresses poses itself")
    g, a = m.refine(val)
    ref = poses_from_imu(val, g, a, STARTS, W)
    p = m.predict(val, STARTS, W)
    np.testing.assert_array_equal(p.q_wxyz, ref.q_wxyz)
    if not m.rotation_only:
        np.testing.assert_array_equal(p.p, ref.p)


def test_refine_and_predict_leave_the_input_alone(fitted, val):
    m, _ = fitted
    before = [x.copy() for x in (val.t_ns, val.gyro, val.acc, val.p, val.v, val.q_wxyz)]
    outputs(m, val)
    assert_same(before, [val.t_ns, val.gyro, val.acc, val.p, val.v, val.q_wxyz])


def test_save_load_round_trip_gives_identical_outputs(name, fitted, val, tmp_path):
    """Saved as evaluate saves it (eval.run.save_method: atomically, under <name><suffix>), loaded
    into a default instance: the file alone carries the configuration and the weights."""
    m, _ = fitted
    f = tmp_path / f"{safe_name(name)}{suffix(name, m)}"
    saved = save_method(m, f)
    assert saved == f.exists() and saved == learns(m)
    m2 = factory(name)().load(f) if saved else factory(name)()
    assert_same(outputs(m, val), outputs(m2, val))


def test_the_same_seed_gives_the_same_fit(name, fitted, crop_split):
    m, log = fitted
    train, val = crop_split
    m2 = make(name)
    log2 = m2.fit([train], [val], SETTINGS)
    assert log2 == log
    assert_same(outputs(m, val), outputs(m2, val))


def test_training_data_shorter_than_the_window_is_a_value_error(name, crop_split):
    m = make(name)
    if not learns(m):
        pytest.skip(f"{name} fits nothing")
    with pytest.raises(ValueError, match="longer than the window"):
        m.fit([cut(crop_split[0], 0, W - 10)], [], SETTINGS)
