"""Schedules the MPC's weights by fuzzy inference: section 3.2, Tables 1-4, eq. (23).

Inputs: lateral error e_Y ∈ [−3, 3] m and heading error e_φ ∈ [−8, 8]° (e_Y = Y − Y_ref, left
of the path positive; e_φ = φ − φ_ref, CCW positive), each with five sets NB NS ZO PS PB.
Outputs: four ratios r ∈ [0, 1] (r_QY, r_Qφ, r_RΔδ, r_RΔMz) with sets ZO PS PM PB.

Figure 3 is not legible in the text; it is read as evenly spaced triangles with shoulders at
the universe ends (the usual reading; docs/mpc.md, "Fuzzy weights"):

    e_Y : NB (−3,−3,−1.5) NS (−3,−1.5,0) ZO (−1.5,0,1.5) PS (0,1.5,3) PB (1.5,3,3)   [m]
    e_φ : NB (−8,−8,−4)   NS (−8,−4,0)   ZO (−4,0,4)     PS (0,4,8)   PB (4,8,8)     [deg]
    r   : ZO (0,0,1/3) PS (0,1/3,2/3) PM (1/3,2/3,1) PB (2/3,1,1)

Rules (Tables 1-4, rows e_φ, columns e_Y), Mamdani: rule strength = min of the two input
memberships, implication = min (clipping), aggregation = max, centroid defuzzification (the
exact centroid of the sampled piecewise-linear aggregate, as ``skfuzzy.defuzz``); membership
functions by ``skfuzzy.trimf``. The weights are eq. (23): Q_Y = r_QY Q_Y,max,
Q_φ = r_Qφ Q_φ,max, R_Δδ = r_RΔδ R_Δδ,max, R_ΔMz = r_RΔMz R_ΔMz,max.

Online, the four response surfaces are tabulated on a grid by a vectorised Mamdani evaluation
and interpolated bilinearly (inputs clipped to the universes). The default :class:`FuzzySpec`'s
surfaces are package data (``fourws_mpc/data/fuzzy_surfaces.npz``, :data:`SHIPPED_SURFACES`)
with a fingerprint of the spec, the sets and the rule tables (:func:`surfaces_fingerprint`); a
file whose fingerprint differs is ignored and the surfaces are computed, so it can never be
silently stale. ``skfuzzy`` is imported only by :func:`mamdani` and the test oracle. After
changing the sets, the rule tables or the default spec, regenerate it with

    python -m fourws_mpc.core.fuzzy_weights --write

(from ``src/fourws_mpc``, or anywhere with the package importable; then ``make setup``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import astuple, dataclass
from pathlib import Path

import numpy as np
from numba import njit

IN_LABELS = ("NB", "NS", "ZO", "PS", "PB")
OUT_LABELS = ("ZO", "PS", "PM", "PB")
OUTPUT_NAMES = ("r_qy", "r_qphi", "r_rddelta", "r_rdmz")

# Tables 1-4: rows e_φ (NB..PB), columns e_Y (NB..PB)
RULE_TABLES: dict[str, tuple[tuple[str, ...], ...]] = {
    "r_qy": (                                          # Table 1
        ("ZO", "PS", "PM", "PS", "ZO"),
        ("ZO", "PS", "PM", "PS", "ZO"),
        ("PS", "PM", "PB", "PM", "PS"),
        ("ZO", "PS", "PM", "PS", "ZO"),
        ("ZO", "PS", "PM", "PS", "ZO"),
    ),
    "r_qphi": (                                        # Table 2
        ("PB", "PM", "PS", "PS", "ZO"),
        ("PM", "PS", "ZO", "PS", "ZO"),
        ("PS", "ZO", "ZO", "PM", "PS"),
        ("PM", "PS", "ZO", "PS", "ZO"),
        ("PB", "PM", "PS", "PS", "ZO"),
    ),
    "r_rddelta": (                                     # Table 3
        ("PM", "PS", "ZO", "PS", "PM"),
        ("PB", "PM", "PS", "PM", "PB"),
        ("PB", "PM", "PS", "PM", "PB"),
        ("PB", "PM", "PS", "PM", "PB"),
        ("PM", "PS", "ZO", "PS", "PM"),
    ),
    "r_rdmz": (                                        # Table 4
        ("PB", "PM", "PS", "PS", "ZO"),
        ("PB", "PM", "PS", "PS", "ZO"),
        ("PM", "PS", "ZO", "PS", "PM"),
        ("ZO", "PS", "PM", "PM", "PB"),
        ("ZO", "PS", "PM", "PB", "PB"),
    ),
}


def even_triangles(lo: float, hi: float, n: int) -> list[tuple[float, float, float]]:
    """n evenly spaced triangles on [lo, hi] with shoulders at the ends: (a, b, c) each."""
    c = np.linspace(lo, hi, n)
    h = c[1] - c[0]
    return [(max(lo, ci - h), ci, min(hi, ci + h)) for ci in c]


@dataclass(frozen=True)
class FuzzySpec:
    """Universes and resolution of the fuzzy weight scheduler."""

    e_y_range_m: float = 3.0
    e_phi_range_deg: float = 8.0
    grid_y: int = 121
    grid_phi: int = 161
    out_points: int = 201

    def input_sets(self) -> tuple[list, list]:
        """Triangles (a, b, c) of e_Y (m) and e_φ (deg)."""
        return (even_triangles(-self.e_y_range_m, self.e_y_range_m, 5),
                even_triangles(-self.e_phi_range_deg, self.e_phi_range_deg, 5))


OUT_SETS = even_triangles(0.0, 1.0, 4)


def _centroid(x: np.ndarray, mf: np.ndarray) -> np.ndarray:
    """Exact centroid of piecewise-linear memberships sampled at x; mf (..., M) → (...)."""
    dx = np.diff(x)
    y1, y2 = mf[..., :-1], mf[..., 1:]
    area = 0.5 * dx * (y1 + y2)
    moment = 0.5 * dx * ((y1 + y2) * x[:-1] + dx * (y1 + 2.0 * y2) / 3.0)
    return moment.sum(-1) / np.maximum(area.sum(-1), np.finfo(float).eps)


def mamdani(e_y: np.ndarray, e_phi_deg: np.ndarray, spec: FuzzySpec | None = None,
            chunk: int = 1024) -> np.ndarray:
    """Vectorised Mamdani min-max / centroid evaluation at points (e_Y m, e_φ deg).

    e_y, e_phi_deg: arrays of one shape S (clipped to the universes). Returns (4, *S) ratios in
    the order of :data:`OUTPUT_NAMES`.
    """
    spec = spec if spec is not None else FuzzySpec()
    sets_y, sets_p = spec.input_sets()
    ey = np.clip(np.asarray(e_y, float), -spec.e_y_range_m, spec.e_y_range_m)
    ep = np.clip(np.asarray(e_phi_deg, float), -spec.e_phi_range_deg, spec.e_phi_range_deg)
    import skfuzzy  # here, not at module level: its import costs ~0.2 s (module docstring)

    shape = np.broadcast_shapes(ey.shape, ep.shape)
    ey = np.broadcast_to(ey, shape).reshape(-1)
    ep = np.broadcast_to(ep, shape).reshape(-1)
    mu_y = np.stack([skfuzzy.trimf(ey, abc) for abc in sets_y], axis=1)      # (G, 5)
    mu_p = np.stack([skfuzzy.trimf(ep, abc) for abc in sets_p], axis=1)      # (G, 5)
    strength = np.minimum(mu_p[:, :, None], mu_y[:, None, :])               # (G, row φ, col Y)
    xo = np.linspace(0.0, 1.0, spec.out_points)
    mf_out = np.stack([skfuzzy.trimf(xo, abc) for abc in OUT_SETS])         # (4, M)
    out = np.empty((len(OUTPUT_NAMES), ey.size))
    for k, name in enumerate(OUTPUT_NAMES):
        table = np.array([[OUT_LABELS.index(c) for c in row] for row in RULE_TABLES[name]])
        act = np.stack([np.where(table == t, strength, 0.0).max(axis=(1, 2))
                        for t in range(len(OUT_LABELS))], axis=1)            # (G, 4)
        for s0 in range(0, ey.size, chunk):
            a = act[s0:s0 + chunk]
            agg = np.minimum(a[:, :, None], mf_out[None, :, :]).max(axis=1)    # (g, M)
            out[k, s0:s0 + chunk] = _centroid(xo, agg)
    return out.reshape((len(OUTPUT_NAMES), *shape))


def surface_grid(spec: FuzzySpec) -> tuple[np.ndarray, np.ndarray]:
    """The e_Y (m) and e_φ (deg) nodes of the response surfaces, (grid_y,), (grid_phi,)."""
    return (np.linspace(-spec.e_y_range_m, spec.e_y_range_m, spec.grid_y),
            np.linspace(-spec.e_phi_range_deg, spec.e_phi_range_deg, spec.grid_phi))


#: The default spec's response surfaces as package data (module docstring).
SHIPPED_SURFACES = Path(__file__).resolve().parent.parent / "data" / "fuzzy_surfaces.npz"


def surfaces_fingerprint(spec: FuzzySpec) -> str:
    """Everything the response surfaces of ``spec`` depend on, as text: the spec, the input
    and output sets, the labels and the rule tables (a shipped table is used only for the
    same fingerprint)."""
    def sets(triangles: list) -> tuple:  # plain floats: the text is numpy's repr-free
        return tuple(tuple(float(v) for v in abc) for abc in triangles)

    return repr((astuple(spec), *(sets(s) for s in spec.input_sets()), sets(OUT_SETS),
                 IN_LABELS, OUT_LABELS, OUTPUT_NAMES,
                 tuple((k, RULE_TABLES[k]) for k in OUTPUT_NAMES)))


def compute_surfaces(spec: FuzzySpec) -> np.ndarray:
    """The four ratios of :func:`mamdani` on the spec's (grid_y × grid_phi) grid, shape
    (4, ny, nφ) (~0.3 s for the default spec)."""
    EY, EP = np.meshgrid(*surface_grid(spec), indexing="ij")
    return mamdani(EY, EP, spec)


def load_shipped_surfaces(spec: FuzzySpec, path: Path = SHIPPED_SURFACES) -> np.ndarray | None:
    """The surfaces of ``spec`` from the shipped file, or None when the file is missing,
    unreadable, or was made for another fingerprint (:func:`surfaces_fingerprint`)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            if str(data["fingerprint"]) != surfaces_fingerprint(spec):
                return None
            surfaces = np.array(data["surfaces"], dtype=float)
    except (OSError, KeyError, ValueError):
        return None
    expected = (len(OUTPUT_NAMES), spec.grid_y, spec.grid_phi)
    return surfaces if surfaces.shape == expected else None


def write_shipped_surfaces(path: Path = SHIPPED_SURFACES, spec: FuzzySpec | None = None) -> Path:
    """Compute the default spec's surfaces and write them with their fingerprint to ``path``
    (the package data file by default); returns ``path``."""
    spec = spec if spec is not None else FuzzySpec()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        np.savez_compressed(fh, surfaces=compute_surfaces(spec),
                            fingerprint=np.array(surfaces_fingerprint(spec)))
    return path


@functools.lru_cache(maxsize=8)
def response_surfaces(spec: FuzzySpec) -> np.ndarray:
    """The four ratios of :func:`mamdani` on the spec's (grid_y × grid_phi) grid, shape
    (4, ny, nφ), read-only: the shipped table when it was made for this spec
    (:func:`load_shipped_surfaces`), else computed (:func:`compute_surfaces`). Cached per
    spec (a frozen dataclass): every controller built in a process with the same spec
    shares one surface (a sweep builds a controller per run)."""
    surfaces = load_shipped_surfaces(spec)
    if surfaces is None:
        surfaces = compute_surfaces(spec)
    surfaces.flags.writeable = False
    return surfaces


class FuzzyWeights:
    """Precomputed response surfaces of Tables 1-4 with bilinear online interpolation."""

    def __init__(self, spec: FuzzySpec | None = None) -> None:
        self.spec = spec if spec is not None else FuzzySpec()
        s = self.spec
        self.gy, self.gp = surface_grid(s)
        self.surfaces = response_surfaces(s)                                 # (4, ny, np)
        self._hy = self.gy[1] - self.gy[0]
        self._hp = self.gp[1] - self.gp[0]

    def ratios(self, e_y_m: float, e_phi_rad: float) -> np.ndarray:
        """The four ratios (r_QY, r_Qφ, r_RΔδ, r_RΔMz) at (e_Y m, e_φ rad), shape (4,)."""
        s = self.spec
        if math.isnan(e_y_m) or math.isnan(e_phi_rad):
            raise ValueError(f"fuzzy weights: NaN error (e_Y {e_y_m!r}, e_φ {e_phi_rad!r})")
        return _bilinear(self.surfaces, float(e_y_m), math.degrees(e_phi_rad), s.e_y_range_m,
                         s.e_phi_range_deg, self._hy, self._hp)


@njit(cache=True)
def _bilinear(surfaces: np.ndarray, e_y_m: float, e_phi_deg: float, range_y_m: float,
              range_phi_deg: float, h_y_m: float, h_phi_deg: float) -> np.ndarray:
    """:meth:`FuzzyWeights.ratios`, compiled: the four surfaces (4, n_y, n_φ) on their
    uniform grid (steps h), interpolated bilinearly at the errors clamped to the ranges (not
    NaN: the caller checks)."""
    n_y, n_phi = surfaces.shape[1], surfaces.shape[2]
    fy = (min(max(e_y_m, -range_y_m), range_y_m) + range_y_m) / h_y_m
    fp = (min(max(e_phi_deg, -range_phi_deg), range_phi_deg) + range_phi_deg) / h_phi_deg
    iy = min(int(fy), n_y - 2)
    ip = min(int(fp), n_phi - 2)
    ty = fy - iy
    tp = fp - ip
    out = np.empty(surfaces.shape[0])
    for k in range(surfaces.shape[0]):
        S = surfaces[k]
        out[k] = ((1 - ty) * ((1 - tp) * S[iy, ip] + tp * S[iy, ip + 1])
                  + ty * ((1 - tp) * S[iy + 1, ip] + tp * S[iy + 1, ip + 1]))
    return out


def skfuzzy_control_system(spec: FuzzySpec | None = None, in_points: int = 161):
    """The same rule base as a ``skfuzzy.control.ControlSystem`` (an oracle for tests).

    Returns ``(system, consequent_names)``; inputs are named ``e_y`` (m) and ``e_phi`` (deg).
    """
    import skfuzzy
    from skfuzzy import control as ctrl

    spec = spec if spec is not None else FuzzySpec()
    sets_y, sets_p = spec.input_sets()
    ey = ctrl.Antecedent(np.linspace(-spec.e_y_range_m, spec.e_y_range_m, in_points), "e_y")
    ep = ctrl.Antecedent(np.linspace(-spec.e_phi_range_deg, spec.e_phi_range_deg, in_points),
                         "e_phi")
    for lab, abc in zip(IN_LABELS, sets_y, strict=True):
        ey[lab] = skfuzzy.trimf(ey.universe, abc)
    for lab, abc in zip(IN_LABELS, sets_p, strict=True):
        ep[lab] = skfuzzy.trimf(ep.universe, abc)
    outs = {}
    for name in OUTPUT_NAMES:
        c = ctrl.Consequent(np.linspace(0.0, 1.0, spec.out_points), name,
                            defuzzify_method="centroid")
        for lab, abc in zip(OUT_LABELS, OUT_SETS, strict=True):
            c[lab] = skfuzzy.trimf(c.universe, abc)
        outs[name] = c
    rules = []
    for name in OUTPUT_NAMES:
        for i, row in enumerate(RULE_TABLES[name]):
            for j, lab in enumerate(row):
                rules.append(ctrl.Rule(ep[IN_LABELS[i]] & ey[IN_LABELS[j]], outs[name][lab]))
    return ctrl.ControlSystem(rules), OUTPUT_NAMES


def main(argv: list[str] | None = None) -> int:
    """``python -m fourws_mpc.core.fuzzy_weights --write [PATH]``: regenerate the shipped
    surfaces (:func:`write_shipped_surfaces`); ``--check``: exit 1 if the shipped file is not
    the default spec's surfaces (to 1e-12)."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m fourws_mpc.core.fuzzy_weights",
                                 description="the shipped fuzzy response surfaces")
    ap.add_argument("--write", action="store_true", help="compute and write the file")
    ap.add_argument("--check", action="store_true", help="compare the file with mamdani()")
    ap.add_argument("path", nargs="?", type=Path, default=SHIPPED_SURFACES)
    args = ap.parse_args(argv)
    spec = FuzzySpec()
    if args.write:
        print(f"wrote {write_shipped_surfaces(args.path, spec)}")
    if args.check or not args.write:
        shipped = load_shipped_surfaces(spec, args.path)
        if shipped is None:
            print(f"{args.path}: missing or made for another spec, sets or rule tables")
            return 1
        err = float(np.abs(shipped - compute_surfaces(spec)).max())
        print(f"{args.path}: largest difference to mamdani() {err:.3g}")
        return 0 if err <= 1e-12 else 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
