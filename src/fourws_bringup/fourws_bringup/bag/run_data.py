"""A recorded run as per-step numpy arrays: :func:`read_run` -> :class:`RunData`.

The per-step topics (:data:`STEP_TOPICS`) become one row per header stamp (the first
message of each stamp, sorted by stamp), after :func:`drop_strays` has left out the
messages off the run's timeline; the reference trajectory, the last ``/run/status`` and the
rejection counts the nodes published on ``/diagnostics`` come along (docs/bags.md,
"Reading").
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fourws_common import topics

from .reader import McapBag

REFERENCE = topics.REFERENCE_TRAJECTORY.name
STATUS = topics.RUN_STATUS.name
DIAGNOSTICS = topics.DIAGNOSTICS.name


def _fields(msg: Any) -> list[str]:
    return [f for f in getattr(msg, "__slots__", ()) if f != "header"]


def _stamp_of(msg: Any) -> int | None:
    header = getattr(msg, "header", None)
    if header is None:
        return None
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _column(values: list[Any]) -> np.ndarray:
    if values and isinstance(values[0], str):
        return np.array(values, dtype=object)
    if values and isinstance(values[0], list | tuple | np.ndarray | bytes):
        try:
            return np.array([np.asarray(v, dtype=float) for v in values], dtype=float)
        except ValueError:
            return np.array(values, dtype=object)
    if values and isinstance(values[0], bool):
        return np.array(values, dtype=bool)
    return np.array(values, dtype=float)


def drop_strays(stamped: list[tuple[int, int, Any]]) -> tuple[list[tuple[int, int, Any]], int]:
    """The messages of one per-step topic that lie on the run's timeline, in receive order,
    and how many did not.

    A timeline is a chain of stamps that each lie within the nodes' jump limit
    (``MAX_STAMP_JUMP_NS``, :class:`fourws_common.input_guard.StampGate`) of its newest one,
    ahead or behind (a late arrival). Every message joins the largest timeline it fits, else
    starts one of its own. The run's timeline is the largest, with every other that was
    received wholly before or after it and the others kept (a node that paused and resumed
    2 s later, or a restarted plant); a timeline received while the run's went on (strays
    stamped far ahead or behind, alone or several in a row, which a node's gate may take for
    a new timeline) is left out, so the analysis grid never stretches to it."""
    from fourws_common.input_guard import MAX_STAMP_JUMP_NS

    lines: list[list[Any]] = []          # [newest stamp, [(receive index, row), ...]]
    for i, row in enumerate(stamped):
        for line in sorted(lines, key=lambda ln: -len(ln[1])):
            if abs(row[0] - line[0]) <= MAX_STAMP_JUMP_NS:
                line[0] = max(line[0], row[0])
                line[1].append((i, row))
                break
        else:
            lines.append([row[0], [(i, row)]])
    kept: list[tuple[int, Any]] = []
    spans: list[tuple[int, int]] = []
    for _, rows in sorted(lines, key=lambda ln: -len(ln[1])):
        lo, hi = rows[0][0], rows[-1][0]
        if all(hi < a or lo > b for a, b in spans):
            spans.append((lo, hi))
            kept += rows
    kept.sort(key=lambda r: r[0])
    return [row for _, row in kept], len(stamped) - len(kept)


def _columns(stamped: list[tuple[int, int, int, Any]]) -> dict[str, np.ndarray]:
    """Per-step columns from ``(stamp_ns, log_time_ns, wall_ns, msg)``: the first message of
    each stamp, sorted by stamp; ``log_ns`` is when the recorder received it (its clock),
    ``wall_ns`` the wall time the step went out (see :class:`RunData`)."""
    first: dict[int, tuple[int, int, Any]] = {}
    for stamp, log_ns, wall_ns, msg in stamped:
        if stamp not in first:
            first[stamp] = (log_ns, wall_ns, msg)
    stamps = sorted(first)
    out: dict[str, np.ndarray] = {"stamp_ns": np.array(stamps, dtype=np.int64),
                                  "t_s": np.array(stamps, dtype=np.int64) * 1e-9,
                                  "log_ns": np.array([first[s][0] for s in stamps],
                                                     dtype=np.int64),
                                  "wall_ns": np.array([first[s][1] for s in stamps],
                                                      dtype=np.int64)}
    if not stamps:
        return out
    for name in _fields(first[stamps[0]][2]):
        out[name] = _column([getattr(first[s][2], name) for s in stamps])
    return out


#: The graph's per-step topics, each with the :class:`RunData` attribute it is read into.
STEP_TOPICS = {topics.VEHICLE_STATE.name: "state",
               topics.VEHICLE_GROUND_TRUTH.name: "ground_truth",
               topics.MPC_COMMAND.name: "mpc_command",
               topics.MPC_DIAGNOSTICS.name: "mpc_diagnostics",
               topics.DRIVE_COMMAND.name: "drive_command",
               topics.WHEEL_TORQUES.name: "wheel_torques"}


@dataclass
class RunData:
    """A recorded run as per-step numpy arrays (SI units, as on the wire).

    Each per-topic dict has ``stamp_ns`` (int64), ``t_s``, ``log_ns`` (int64, the recorder's
    receive time on its clock: simulated in a lockstep run of this version, wall in older
    bags), ``wall_ns`` (int64: the wall time of the message, the bag's ``publish_time`` where
    ``custom_data.fourws_publish_time`` says it is one (the send time; the wall receive time
    in bags of 2026-12-02), else the log time of an older bag, which was the wall receive
    time; what step latencies are measured on) and one array per
    message field (scalars ``(n,)``, wheel arrays ``(n, 4)``, strings as object arrays), one
    row per header stamp (the first message of each stamp), sorted by stamp. A topic absent
    from the bag gives a dict with empty ``stamp_ns``/``t_s``/``log_ns``/``wall_ns`` only.
    """

    path: Path
    state: dict[str, np.ndarray]
    mpc_command: dict[str, np.ndarray]
    mpc_diagnostics: dict[str, np.ndarray]
    drive_command: dict[str, np.ndarray]
    wheel_torques: dict[str, np.ndarray]
    reference: dict[str, np.ndarray] | None
    status: dict[str, Any] | None
    message_counts: dict[str, int]
    #: Rejected inputs per node from /diagnostics: {node: {kind: count}}, the highest count
    #: each node reported (its counters only grow within a run).
    rejections: dict[str, dict[str, int]] = field(default_factory=dict)
    #: Messages per topic off the run's timeline (:func:`drop_strays`), left out above.
    strays: dict[str, int] = field(default_factory=dict)
    #: /vehicle/ground_truth (recorded in a realistic condition only; else no rows)
    ground_truth: dict[str, np.ndarray] = field(default_factory=lambda: _columns([]))

    @property
    def truth(self) -> dict[str, np.ndarray]:
        """The plant's true states: /vehicle/ground_truth where the run published it (a
        realistic condition: /vehicle/state is then what the sensors gave), else
        /vehicle/state (the ideal condition, where the two are the same)."""
        return self.ground_truth if len(self.ground_truth["stamp_ns"]) else self.state

    @property
    def steps(self) -> int:
        """Number of distinct VehicleState stamps."""
        return int(len(self.state["stamp_ns"]))

    @property
    def controller(self) -> str | None:
        """Controller name from the MPC diagnostics (the last one), if recorded."""
        c = self.mpc_diagnostics.get("controller")
        return str(c[-1]) if c is not None and len(c) else None

    @property
    def scenario(self) -> str | None:
        """Scenario name from /run/status, if recorded."""
        return None if not self.status else self.status.get("scenario")


def read_run(path: str | Path) -> RunData:
    """Decode a run folder (``bag/`` inside), a bag folder or a bare ``.mcap`` into arrays.

    A bag recorded in a namespace is read by the topic table's names (``/car1/vehicle/state``
    as ``/vehicle/state``). Raises :class:`BagError` naming the file for a missing, truncated
    or corrupt bag.
    """
    with McapBag(path) as bag:
        # a run recorded in a namespace (/car1/vehicle/state) is read by the table's names
        ns = topics.namespace_of(bag.channels)
        recorded = {topics.graph_name(t, ns): t for t in bag.channels}
        counts = {g: bag.channels[t].message_count for g, t in recorded.items()}
        per: dict[str, list[tuple[int, Any]]] = {t: [] for t in STEP_TOPICS}
        reference = None
        status_text = None
        rejections: dict[str, dict[str, int]] = {}
        wanted = [recorded[t] for t in (*STEP_TOPICS, REFERENCE, STATUS, DIAGNOSTICS)
                  if t in recorded]
        sent = bag.custom_data.get("fourws_publish_time") in ("send_time",
                                                               "wall_receive_time")
        for name, log_ns, pub_ns, msg in bag.decoded(wanted):
            topic = topics.graph_name(name, ns)
            if topic in per:
                stamp = _stamp_of(msg)
                if stamp is not None:
                    per[topic].append((stamp, log_ns, pub_ns if sent else log_ns, msg))
            elif topic == REFERENCE:
                reference = msg
            elif topic == STATUS:
                status_text = msg.data
            elif topic == DIAGNOSTICS:
                _add_rejections(rejections, msg)
        path_out = bag.path
    ref_arrays = None
    if reference is not None:
        ref_arrays = {name: np.asarray(getattr(reference, name), dtype=float)
                      for name in _fields(reference)}
        ref_arrays["stamp_ns"] = np.int64(_stamp_of(reference) or 0)
    status = None
    if status_text is not None:
        try:
            status = json.loads(status_text)
        except ValueError:
            status = {"raw": status_text}
    strays: dict[str, int] = {}
    for t in STEP_TOPICS:
        per[t], n = drop_strays(per[t])
        if n:
            strays[t] = n
    cols = {attr: _columns(per[t]) for t, attr in STEP_TOPICS.items()}
    return RunData(path=path_out, reference=ref_arrays, status=status,
                   message_counts=counts, rejections=rejections, strays=strays, **cols)


def _add_rejections(out: dict[str, dict[str, int]], msg: Any) -> None:
    """Fold one DiagnosticArray's counters (KeyValue value = a count) into ``out``."""
    for st in msg.status:
        if str(st.name).endswith(": runtime"):  # fourws_common.health: text, not counts
            continue
        node = out.setdefault(str(st.name).lstrip("/"), {})
        for kv in st.values:
            try:
                n = int(kv.value)
            except ValueError:
                continue
            node[kv.key] = max(n, node.get(kv.key, 0))
