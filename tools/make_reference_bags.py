"""Copy the bags of a ``fourws paper`` output into bags/ and write bags/README.md.

Usage (after ``source ros_ws/env.sh``)::

    fourws paper --out runs/paper --force
    python tools/make_reference_bags.py runs/paper

The README's metrics are recomputed here from the copied bags, the same way
``tests/integration/test_reference_bags.py`` checks them.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

from fourws_bringup.bag.run_data import read_run
from fourws_bringup.paper import CONDITIONS, PAPER_RUNS, run_dir_name
from fourws_bringup.scoring import bag_metrics

KEYS = ("max_abs_lateral_error_m", "rmse_lateral_error_m", "mae_lateral_error_m",
        "max_abs_heading_error_deg", "rmse_heading_error_deg", "max_abs_sideslip_deg",
        "rmse_sideslip_deg")


def main(src: str) -> int:
    root = Path(__file__).resolve().parents[1] / "bags"
    rows = []
    for ctrl, scen, world in [(c, s, w) for w in CONDITIONS for c, s in PAPER_RUNS]:
        name = run_dir_name(ctrl, scen, world)
        dst = root / name
        if dst.exists():
            shutil.rmtree(dst)
        shutil.copytree(Path(src) / name / "bag", dst)
        run = read_run(dst)
        m = bag_metrics(run)
        status = run.status or {}
        size = sum(f.stat().st_size for f in dst.iterdir()) / 1e6
        rows.append(f"| `{name}` | {m['steps']} | "
                    + " | ".join(f"{m[k]:.6f}" for k in KEYS)
                    + f" | {status.get('completed')} | {size:.2f} |")
    head = ["# Reference runs", "",
            "The eight configurations of `fourws paper` (Tables 6-8) in both worlds (ideal: "
            "`CONTROLLER@SCENARIO`; realistic, noise seed 0: `CONTROLLER@SCENARIO@realistic`, "
            "scored on the recorded `/vehicle/ground_truth`), recorded over topics in "
            "lockstep: rosbag2 layout (`metadata.yaml` + one zstd-chunked `.mcap`, profile "
            "ros2, ros2msg schemas, cdr). Regenerate with:", "",
            "```bash", "source ros_ws/env.sh",
            "fourws paper --out runs/paper --force",
            "python tools/make_reference_bags.py runs/paper", "```", "",
            "Every number below is recomputed from the bag alone by "
            "`tests/integration/test_reference_bags.py` (`fourws report bags/NAME` prints "
            "them too). Lockstep runs are deterministic: a new `fourws paper` reproduces "
            "these to the last digit on the same software.", "",
            "| run | steps | max abs eY m | RMSE eY m | MAE eY m | max abs ephi deg "
            "| RMSE ephi deg | max abs beta deg | RMSE beta deg | completed | size MB |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    (root / "README.md").write_text("\n".join(head + rows) + "\n", encoding="utf-8")
    print(f"wrote {root / 'README.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1] if len(sys.argv) > 1 else "runs/paper"))
