"""Re-run the torque allocation of recorded runs from their bags and compare two methods.

    source ros_ws/env.sh
    python tools/allocation_audit.py bags/improved@dlc_60_mu05 bags/ampc_4ws_dyc@dlc_60_mu05

Prints one JSON object per run (``fourws_bringup.report.allocation_audit``): the recorded
method, how far the recorded wheel torques are from the core's output on the recorded inputs,
how far the other method's torques are from them, the load-ratio rear share and the largest
tyre usage. README.md ("Table 8") quotes these numbers.
"""

from __future__ import annotations

import argparse
import json
import sys

from fourws_bringup.bag.errors import BagError
from fourws_bringup.bag.run_data import read_run
from fourws_bringup.report import allocation_audit


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="run folder, bag folder or .mcap file")
    ap.add_argument("--other", default="rule",
                    help="allocation method to compare with (default: rule)")
    args = ap.parse_args(argv)
    status = 0
    for path in args.runs:
        try:
            audit = allocation_audit(read_run(path), other=args.other)
        except (BagError, ValueError) as exc:
            print(f"{path}: {exc}", file=sys.stderr)
            status = 1
            continue
        print(json.dumps({"run": path, **audit}))
    return status


if __name__ == "__main__":
    sys.exit(main())
