"""The one windowed nearest-point search (fourws_common.path_lookup) and its users."""

from __future__ import annotations

import math

import numpy as np

from fourws_common.path_lookup import PathIndex, nearest_sample, windowed_search
from fourws_mpc.core.reference import Reference
from fourws_sim.core.paths import circle, sine


def _drive(path, n: int = 600, offset_m: float = 1.5, seed: int = 1):
    """Poses along the path, up to ``offset_m`` off it, every few samples."""
    rng = np.random.default_rng(seed)
    idx = np.linspace(0, len(path.x) - 1, n).astype(int)
    off = offset_m * np.sin(np.linspace(0.0, 7.0, n)) + 0.05 * rng.standard_normal(n)
    return (path.x[idx] - off * np.sin(path.yaw[idx]), path.y[idx] + off * np.cos(path.yaw[idx]))


def test_windowed_answer_is_the_full_search_on_a_path_that_does_not_come_back():
    p = sine(14.0)
    index = PathIndex(p.x, p.y)
    for px, py in zip(*_drive(p), strict=True):
        assert index.nearest(px, py) == nearest_sample(p.x, p.y, px, py)


def test_first_call_and_window_edge_search_everything():
    p = sine(14.0)
    index = PathIndex(p.x, p.y, window=50)
    far = len(p.x) - 10
    assert index.nearest(p.x[far], p.y[far]) == far          # first call: full search
    assert index.nearest(p.x[5], p.y[5]) == 5                # window answer on its edge
    calls = []

    def best(lo: int, hi: int) -> tuple[int]:
        calls.append((lo, hi))
        return (nearest_sample(p.x, p.y, p.x[5], p.y[5], lo, hi),)

    assert windowed_search(best, len(p.x), far, 50, 51) == (5,)
    assert calls == [(far - 50, len(p.x)), (0, len(p.x))]


def test_on_a_path_that_comes_back_the_window_keeps_to_its_branch():
    """A full 360° circle ends where its arc began: there the window keeps the branch the car
    is on, where a full search may pick the other (the plant's old per-step argmin did)."""
    p = circle(15.0, radius_m=45.0, lead_in_m=20.0, transition_m=20.0, arc_deg=360.0)
    start = int(np.searchsorted(p.s, 40.0))                   # start of the arc
    index = PathIndex(p.x, p.y)
    index.nearest(p.x[start - 20], p.y[start - 20])
    for k in range(start - 20, start + 20):
        assert abs(index.nearest(p.x[k], p.y[k] + 1e-4) - k) <= 1


def test_mpc_reference_window_gives_the_full_projection_along_a_drive():
    p = sine(14.0)
    ref = Reference.from_arrays(p.x, p.y, p.yaw, p.curvature, p.speed)
    hint = None
    for px, py in zip(*_drive(p), strict=True):
        near = ref.nearest(px, py, hint)
        full = ref.nearest(px, py)
        assert (near.index, near.s, near.lateral_error) == (full.index, full.s,
                                                             full.lateral_error)
        hint = near.index
    assert math.isfinite(near.s)


def test_a_hint_off_the_path_searches_everything():
    calls = []

    def best(lo: int, hi: int) -> tuple[int]:
        calls.append((lo, hi))
        assert lo < hi, "an empty window was searched"
        return (lo,)

    for hint in (100, -1000, 15):            # far beyond the end, before the start, just beyond
        calls.clear()
        assert windowed_search(best, 10, hint, 5, 0) == (0,)
        assert calls == [(0, 10)]


def test_the_mpc_reference_projects_the_same_with_a_hint_off_its_path():
    x = np.linspace(0.0, 10.0, 11)
    ref = Reference.from_arrays(x, np.zeros(11), np.zeros(11), np.zeros(11), np.full(11, 5.0))
    free = ref.nearest(8.3, 0.5)
    for hint in (100, -1000):
        near = ref.nearest(8.3, 0.5, hint)
        assert near.index == free.index == 8
        assert math.isclose(near.s, 8.3) and math.isclose(near.lateral_error, 0.5)
