"""Where do the controllers separate? The five presets on many conditions, in-process.

Runs ``fourws_bringup.core.closed_loop.run_closed_loop`` (the same cores, in the graph's
lockstep order; the graph reproduces it to 1e-9) for every controller preset on:

- ``scaling``: the two paper scenarios with the output sizes of the cost scaling (s_Y, s_φ)
  multiplied by k (k = 1 is the shipped equal-effect scaling; k < 1 weights tracking more);
- ``mismatch``: the two paper scenarios with the MPC's prediction model wrong on purpose
  (cornering stiffness ×0.7 and ×1.3, mass and yaw inertia ×1.2), the plant unchanged;
- ``scenarios``: the other shipped scenarios (ISO 3888 at 80 km/h, μ step, split μ, sine).

Writes every run's metrics to ``OUT.json`` and the tables to ``OUT.md``. Nothing is tuned:
each case changes one documented thing for all presets alike.

    python tools/ranking_study.py docs/ranking-study      # about 3 min on 2 cores
"""

from __future__ import annotations

import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from fourws_bringup.paper import PAPER_RUNS  # noqa: E402

PRESETS = list(dict.fromkeys(c for c, _ in PAPER_RUNS))  # the paper's order
PAPER = ["dlc_60_mu05", "dlc_90_mu06"]


def cases() -> list[tuple[str, str, str, dict]]:
    """(group, label, scenario, overrides): MPC overrides relative to the shipped
    fourws_mpc/mpc.yaml; the key ``vehicle`` holds plant overrides over vehicle.yaml."""
    from fourws_bringup.core.configs import load_mpc_config
    from fourws_sim.core.vehicle_params import load_vehicle_params

    cfg = load_mpc_config("improved", None)
    S_Y, S_PHI = cfg.scale_y_m, cfg.scale_phi_deg  # noqa: N806
    C_F = cfg.cornering_stiffness_front_static_n_per_rad  # noqa: N806
    C_R = cfg.cornering_stiffness_rear_static_n_per_rad  # noqa: N806
    M, IZ = cfg.mass_kg, cfg.yaw_inertia_kg_m2  # noqa: N806
    out = []
    for k in (0.1, 0.3, 1.0, 3.0, 10.0):
        for sc in PAPER:
            out.append(("scaling", f"k = {k:g}", sc,
                        {"scale_y_m": S_Y * k, "scale_phi_deg": S_PHI * k}))
    for label, ov in (("C_alpha x0.7", {"cornering_stiffness_front_static_n_per_rad": 0.7 * C_F,
                                         "cornering_stiffness_rear_static_n_per_rad": 0.7 * C_R}),
                      ("C_alpha x1.3", {"cornering_stiffness_front_static_n_per_rad": 1.3 * C_F,
                                         "cornering_stiffness_rear_static_n_per_rad": 1.3 * C_R}),
                      ("m, Iz x1.2", {"mass_kg": 1.2 * M, "yaw_inertia_kg_m2": 1.2 * IZ})):
        for sc in PAPER:
            out.append(("mismatch", label, sc, ov))
    for sc in ("iso3888_80_mu08", "mu_step", "split_mu", "sine_50_mu08"):
        out.append(("scenarios", "shipped", sc, {}))
    p_ty1 = load_vehicle_params().tyre_relaxation_peak_over_radius
    for f in (0.0, 0.5, 1.0, 2.0):
        for sc in PAPER:
            out.append(("relaxation", f"p_Ty1 x{f:g}", sc,
                        {"vehicle": {"tyre_relaxation_peak_over_radius": f * p_ty1}}))
    return out


def scenario_with_vehicle(name: str, vehicle: dict, folder: Path) -> str:
    """Path of a copy of the shipped scenario ``name`` with ``vehicle`` merged over its own
    vehicle overrides."""
    import yaml

    from fourws_common.params import read_yaml_file
    from fourws_sim.core.scenario import scenarios_dir

    data = read_yaml_file(scenarios_dir() / f"{name}.yaml")
    data["vehicle"] = {**(data.get("vehicle") or {}), **vehicle}
    tag = "_".join(f"{k}-{v:g}" for k, v in sorted(vehicle.items()))
    path = folder / f"{name}__{tag}.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return str(path)


def run_one(job: tuple[str, str, str, dict, str]) -> dict:
    import tempfile

    from fourws_bringup.core.closed_loop import run_closed_loop

    group, label, scenario, overrides, preset = job
    row = {"group": group, "case": label, "scenario": scenario, "controller": preset,
           "overrides": overrides}
    mpc = {k: v for k, v in overrides.items() if k != "vehicle"}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            source = (scenario_with_vehicle(scenario, overrides["vehicle"], Path(tmp))
                      if "vehicle" in overrides else scenario)
            log = run_closed_loop(source, preset, mpc_overrides=mpc or None)
    except Exception as exc:  # noqa: BLE001 - a failed case is a result, recorded as such
        row["error"] = f"{type(exc).__name__}: {exc}"
        return row
    m = log.metrics()
    row.update({k: m[k] for k in ("completed", "reason", "max_abs_lateral_error_m",
                                  "rmse_lateral_error_m", "max_abs_heading_error_deg",
                                  "max_abs_sideslip_deg", "rmse_sideslip_deg")})
    row["np_max"] = int(max(log.mpc["np"]))
    row["nc_max"] = int(max(log.mpc["nc"]))
    row["mpc_fallbacks"] = int(sum(log.mpc["fallback"]))
    return row


def _cell(r: dict) -> str:
    if "error" in r:
        return "error"
    s = f"{1000 * r['max_abs_lateral_error_m']:.1f} / {1000 * r['rmse_lateral_error_m']:.1f}"
    return s if r["completed"] else s + " (aborted)"


def markdown(rows: list[dict]) -> str:
    lines = ["# Where the controllers separate: generated tables", "",
             "Generated by `source ros_ws/env.sh && python tools/ranking_study.py "
             "docs/ranking-study` (in-process closed loop, deterministic; every run's metrics "
             "in `ranking-study.json`). Reading: `docs/mpc.md`, \"Where the controllers "
             "separate\".", "",
             "Max |eY| / RMSE eY in mm. Cells marked (aborted) hit the plant's abort limits.",
             ""]
    for group in ("relaxation", "scaling", "mismatch", "scenarios"):
        sel = [r for r in rows if r["group"] == group]
        keys = list(dict.fromkeys((r["case"], r["scenario"]) for r in sel))
        lines += [f"### {group}", "", "| case | scenario | " + " | ".join(PRESETS) + " |",
                  "|---|---|" + "---|" * len(PRESETS)]
        for case, sc in keys:
            by = {r["controller"]: r for r in sel if r["case"] == case and r["scenario"] == sc}
            lines.append(f"| {case} | {sc} | " + " | ".join(_cell(by[p]) for p in PRESETS) + " |")
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    out = Path(argv[1] if len(argv) > 1 else "ranking-study")
    jobs = [(*c, p) for c in cases() for p in PRESETS]
    rows = []
    with ProcessPoolExecutor(2) as ex:
        for i, row in enumerate(ex.map(run_one, jobs), 1):
            rows.append(row)
            print(f"\r{i}/{len(jobs)} {row['case']} {row['scenario']} {row['controller']}   ",
                  end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    out.with_suffix(".json").write_text(json.dumps(rows, indent=1))
    out.with_suffix(".md").write_text(markdown(rows))
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv))
