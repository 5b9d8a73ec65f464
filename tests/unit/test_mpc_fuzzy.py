"""Fuzzy weights, section 3.2: precomputed surfaces against skfuzzy's ControlSystemSimulation."""

import math

import numpy as np
import pytest
from skfuzzy import control as ctrl

from fourws_mpc.core.fuzzy_weights import (
    OUT_LABELS,
    OUTPUT_NAMES,
    RULE_TABLES,
    FuzzyWeights,
    mamdani,
    skfuzzy_control_system,
)


@pytest.fixture(scope="module")
def fw():
    return FuzzyWeights()


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_online_surfaces_match_skfuzzy_control_system(fw):
    system, names = skfuzzy_control_system()
    sim = ctrl.ControlSystemSimulation(system)
    rng = np.random.default_rng(42)
    pts = np.column_stack([rng.uniform(-3, 3, 200), rng.uniform(-8, 8, 200)])
    pts = np.vstack([pts, [[0, 0], [3, 8], [-3, -8], [1.5, -4], [0.07, 1.3]]])
    worst = 0.0
    for e_y, e_phi_deg in pts:
        sim.input["e_y"] = e_y
        sim.input["e_phi"] = e_phi_deg
        sim.compute()
        expected = np.array([sim.output[n] for n in names])
        got = fw.ratios(e_y, math.radians(e_phi_deg))
        worst = max(worst, float(np.abs(got - expected).max()))
    assert worst < 0.01          # 1 % of the output range [0, 1]


def test_rule_tables_shape_and_labels():
    for name in OUTPUT_NAMES:
        t = RULE_TABLES[name]
        assert len(t) == 5 and all(len(row) == 5 for row in t)
        assert all(c in OUT_LABELS for row in t for c in row)


def test_single_rule_points_give_the_set_centroids(fw):
    # at the ZO/ZO vertex only the centre rule fires: PB, ZO, PS, ZO (Tables 1-4)
    c = {"ZO": 1 / 9, "PS": 1 / 3, "PM": 2 / 3, "PB": 8 / 9}
    np.testing.assert_allclose(fw.ratios(0.0, 0.0), [c["PB"], c["ZO"], c["PS"], c["ZO"]],
                               atol=1e-3)
    # e_Y = PB, e_φ = NB corner: Table 1 ZO, Table 2 ZO, Table 3 PM, Table 4 ZO
    np.testing.assert_allclose(fw.ratios(3.0, math.radians(-8.0)),
                               [c["ZO"], c["ZO"], c["PM"], c["ZO"]], atol=1e-3)
    # e_Y = NB, e_φ = NB corner: ZO, PB, PM, PB
    np.testing.assert_allclose(fw.ratios(-3.0, math.radians(-8.0)),
                               [c["ZO"], c["PB"], c["PM"], c["PB"]], atol=1e-3)


def test_inputs_are_clipped_to_the_universes(fw):
    np.testing.assert_allclose(fw.ratios(10.0, 1.0), fw.ratios(3.0, math.radians(8.0)))
    np.testing.assert_allclose(fw.ratios(-10.0, -1.0), fw.ratios(-3.0, math.radians(-8.0)))


def test_ratios_lie_in_unit_interval_and_grid_is_exact_at_nodes(fw):
    s = fw.surfaces
    assert s.min() >= 0.0 and s.max() <= 1.0
    iy, ip = 37, 101
    direct = mamdani(np.array(fw.gy[iy]), np.array(fw.gp[ip]))
    np.testing.assert_allclose(fw.ratios(fw.gy[iy], math.radians(fw.gp[ip])), direct,
                               atol=1e-9)


def test_controllers_with_one_spec_share_one_read_only_surface():
    """The response surface is built once per spec and process (a sweep builds a controller
    per run); nobody can change it under another controller."""
    import dataclasses

    from fourws_mpc.core.fuzzy_weights import FuzzySpec, FuzzyWeights

    a, b = FuzzyWeights(FuzzySpec()), FuzzyWeights(FuzzySpec())
    assert a.surfaces is b.surfaces and not a.surfaces.flags.writeable
    other = FuzzyWeights(dataclasses.replace(FuzzySpec(), e_y_range_m=1.0))
    assert other.surfaces is not a.surfaces
    assert other.ratios(0.5, 0.0)[0] != a.ratios(0.5, 0.0)[0]


def test_shipped_surfaces_equal_mamdani_on_the_grid():
    """The package data the MPC loads at start-up is the default spec's surfaces, so it can
    never drift from the rule base (regenerate: ``python -m fourws_mpc.core.fuzzy_weights
    --write``)."""
    import numpy as np

    from fourws_mpc.core.fuzzy_weights import (
        SHIPPED_SURFACES,
        FuzzySpec,
        load_shipped_surfaces,
        surface_grid,
    )

    spec = FuzzySpec()
    shipped = load_shipped_surfaces(spec)
    assert shipped is not None, f"{SHIPPED_SURFACES} missing or made for another rule base"
    EY, EP = np.meshgrid(*surface_grid(spec), indexing="ij")
    np.testing.assert_allclose(shipped, mamdani(EY, EP, spec), rtol=0.0, atol=1e-12)


def test_shipped_surfaces_are_used_only_for_their_own_spec(tmp_path):
    """Another spec, a file for other rules or no file at all: the surfaces are computed."""
    import dataclasses

    from fourws_mpc.core.fuzzy_weights import (
        FuzzySpec,
        compute_surfaces,
        load_shipped_surfaces,
        response_surfaces,
        write_shipped_surfaces,
    )

    spec = FuzzySpec()
    small = dataclasses.replace(spec, grid_y=7, grid_phi=9)
    assert load_shipped_surfaces(small) is None
    np.testing.assert_array_equal(response_surfaces(small), compute_surfaces(small))
    path = write_shipped_surfaces(tmp_path / "s.npz", small)
    np.testing.assert_array_equal(load_shipped_surfaces(small, path), compute_surfaces(small))
    assert load_shipped_surfaces(spec, path) is None           # made for another spec
    assert load_shipped_surfaces(spec, tmp_path / "none.npz") is None
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    assert load_shipped_surfaces(spec, tmp_path / "bad.npz") is None


def test_importing_the_fuzzy_weights_does_not_import_skfuzzy():
    """skfuzzy (and the scipy it pulls in) costs ~0.2 s of every MPC and CLI start; only the
    Mamdani computation and the test oracle import it."""
    import subprocess
    import sys

    code = ("import sys; import fourws_mpc.core.fuzzy_weights as f; f.FuzzyWeights(); "
            "print('skfuzzy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env=_source_env())
    assert out.stdout.strip() == "False"


def _source_env() -> dict:
    import os
    from pathlib import Path

    src = Path(__file__).resolve().parents[2] / "src" / "fourws_mpc"
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(src), env.get("PYTHONPATH", "")]))
    return env


def test_the_compiled_lookup_is_bilinear_interpolation_of_the_surfaces(fw):
    """``ratios`` (compiled) against scipy's linear interpolation on the same grid, inside
    and beyond the universes (clamped to their edges)."""
    from scipy.interpolate import RegularGridInterpolator

    s = fw.spec
    rng = np.random.default_rng(5)
    e_y = rng.uniform(-1.5 * s.e_y_range_m, 1.5 * s.e_y_range_m, 300)
    e_phi = rng.uniform(-1.5 * s.e_phi_range_deg, 1.5 * s.e_phi_range_deg, 300)
    at = np.column_stack([np.clip(e_y, -s.e_y_range_m, s.e_y_range_m),
                          np.clip(e_phi, -s.e_phi_range_deg, s.e_phi_range_deg)])
    got = np.array([fw.ratios(y, math.radians(p)) for y, p in zip(e_y, e_phi, strict=True)])
    for k in range(len(OUTPUT_NAMES)):
        oracle = RegularGridInterpolator((fw.gy, fw.gp), fw.surfaces[k])
        np.testing.assert_allclose(got[:, k], oracle(at), rtol=0, atol=1e-12)
