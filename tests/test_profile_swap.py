"""experiments/profile_swap.py: the parts a swap names add up to the matrix, and a split's parts to the difference."""
import importlib
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
ps = importlib.import_module("profile_swap")


def _profile(rng: np.random.Generator) -> dict:
    m = (np.eye(3) + 1e-3 * rng.standard_normal((3, 3))).tolist()
    g = (1e-4 * rng.standard_normal((3, 3))).tolist()
    return {"floor": {"M_g": m, "G": g}, "gyroscope": {"matrix": m}, "g_sensitivity_rad_s_per_mps2": g}


def test_matrix_parts_add_up_and_have_their_symmetry():
    m = np.random.default_rng(0).standard_normal((3, 3))
    diag, skew, sym = (ps._part(m, t) for t in ("M_g_diag", "M_g_skew", "M_g_sym"))
    np.testing.assert_allclose(diag + skew + sym, m, atol=1e-15)
    np.testing.assert_allclose(skew, -skew.T)
    np.testing.assert_allclose(sym, sym.T)
    assert np.all(np.diag(skew) == 0) and np.all(np.diag(sym) == 0)
    np.testing.assert_allclose(sum(ps._part(m, f"M_g_c{j}") for j in range(3)), m, atol=1e-15)
    np.testing.assert_array_equal(ps._part(m, "G_c1")[:, 1], m[:, 1])


@pytest.mark.parametrize("terms", [("M_g_diag", "M_g_skew", "M_g_sym"), ("M_g_c0", "M_g_c1", "M_g_c2")])
def test_every_part_swapped_gives_the_donors_matrix(terms):
    rng = np.random.default_rng(1)
    base, donor = _profile(rng), _profile(rng)
    p = base
    for t in terms:
        p = ps.swap(p, donor, t)
    np.testing.assert_allclose(p["floor"]["M_g"], donor["floor"]["M_g"], atol=1e-15)
    np.testing.assert_allclose(p["gyroscope"]["matrix"], donor["floor"]["M_g"], atol=1e-15)
    np.testing.assert_array_equal(p["floor"]["G"], base["floor"]["G"])
    one = ps.swap(base, donor, "M_g_skew")  # one part: the base's other parts kept, the base itself untouched
    np.testing.assert_allclose(ps._part(np.array(one["floor"]["M_g"]), "M_g_sym"),
                               ps._part(np.array(base["floor"]["M_g"]), "M_g_sym"))
    assert base["floor"]["M_g"] != donor["floor"]["M_g"]


def test_g_columns_swapped():
    rng = np.random.default_rng(2)
    base, donor = _profile(rng), _profile(rng)
    p = ps.swap(base, donor, "G_c2")
    g = np.array(p["g_sensitivity_rad_s_per_mps2"])
    np.testing.assert_array_equal(g[:, 2], np.array(donor["floor"]["G"])[:, 2])
    np.testing.assert_array_equal(g[:, :2], np.array(base["floor"]["G"])[:, :2])
    np.testing.assert_array_equal(p["floor"]["G"], g)


def test_level_parts_add_up():
    rng = np.random.default_rng(3)
    d = rng.standard_normal((500, 3)) + [0.3, -0.2, 0.1]
    up = np.array([0.9, 0.1, -0.3])
    parts = ps.level_parts(d, up)
    np.testing.assert_allclose(parts["mean"] + parts["varying"], d, atol=1e-12)
    np.testing.assert_allclose(parts["mean_along_g"] + parts["mean_across_g"], parts["mean"], atol=1e-15)
    np.testing.assert_allclose(np.cross(parts["mean_along_g"][0], up), 0, atol=1e-15)
    assert abs(parts["mean_across_g"][0] @ up) < 1e-14
    np.testing.assert_allclose(parts["varying"].mean(axis=0), 0, atol=1e-15)
