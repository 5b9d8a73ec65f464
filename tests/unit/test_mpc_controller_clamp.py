"""The controller's command clamp (``controller._clamp_enabled``) against numpy's clip: each
input into its bounds, a disabled one at zero."""

from __future__ import annotations

import numpy as np

from fourws_mpc.core.controller import _clamp_enabled


def test_the_clamp_is_numpys_clip_with_the_disabled_inputs_at_zero():
    rng = np.random.default_rng(2)
    for _ in range(500):
        u = rng.normal(scale=2.0, size=3)
        lo = -rng.uniform(0.0, 1.5, 3)
        hi = rng.uniform(0.0, 1.5, 3)
        enabled = rng.integers(0, 2, 3).astype(bool)
        np.testing.assert_array_equal(_clamp_enabled(u, enabled, lo, hi),
                                      np.where(enabled, np.clip(u, lo, hi), 0.0))
