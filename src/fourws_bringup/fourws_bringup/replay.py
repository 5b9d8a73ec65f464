"""``fourws replay``: start replay_node on a bag in the current (or given) ROS domain.

The replay is described in docs/bags.md, "Replay".
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

from .supervisor import NodeDied, NodeSpec, Supervisor


def replay_cli(bag: str, *, rate: float = 1.0, topics: list[str] | None = None,
               domain_id: int | None = None) -> int:
    """Publish a bag's topics again with /clock at ``rate``; returns when the bag is done."""
    path = Path(bag).resolve()
    if not path.exists():
        print(f"fourws replay: {path}: no such bag", file=sys.stderr)
        return 2
    did = domain_id if domain_id is not None else int(os.environ.get("ROS_DOMAIN_ID", "0"))
    params: dict[str, object] = {"bag": str(path), "rate": float(rate)}
    if topics:
        params["topics"] = "[" + ",".join(topics) + "]"
    spec = NodeSpec("replay_node", "fourws_bringup", "replay_node", parameters=params)
    sup = Supervisor([spec], did, Path(tempfile.mkdtemp(prefix="fourws-replay-")))
    try:
        sup.start()
        print(f"replaying {path} at rate {rate} in ROS_DOMAIN_ID {did}", file=sys.stderr)
        rc = sup.wait_exit("replay_node")
        for line in sup.procs["replay_node"].last_lines(3):
            print(line, file=sys.stderr)
        return rc
    except NodeDied as exc:
        print(exc, file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    finally:
        sup.stop()
