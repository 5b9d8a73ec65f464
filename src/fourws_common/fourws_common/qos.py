"""Named QoS profiles of the fourws graph, one reason each."""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# Per-step control and state traffic: reliable so lockstep never loses a step; a deep queue
# (10 s of steps) so a subscriber starved of CPU for a while (the recorder, with six processes
# on two cores at several times real time) catches up instead of dropping: at depth 100 the
# recorder lost up to 10 % of the steps of a run under load. Loss is still detected from the
# bag (``missing_steps`` in metrics.json) and logged by the recorder.
CONTROL_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

# Reference trajectory and path: published once; late joiners (the recorder, rviz) must get it.
LATCHED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)

# /clock: reliable in lockstep so sim-time users see every tick; depth as the control traffic.
CLOCK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

# Controllers' view of the vehicle state: only the newest matters. Keep-last 1 means a node
# that fell behind (a stalled MPC in realtime) takes the newest state, not a backlog of old
# ones; in lockstep one state is in flight at a time, so nothing is lost.
LATEST_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

# /diagnostics: as diagnostic_updater publishes it (reliable, volatile), a queue of 10.
DIAGNOSTICS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
