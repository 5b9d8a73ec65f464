"""Graph supervisor: start fourws nodes as ordinary processes, watch them, stop them cleanly.

This is the small replacement for ``ros2 launch`` on machines without ``launch_ros``. Each
node is the same executable ``ros2 run <package> <executable>`` would start
(``<prefix>/lib/<package>/<executable>``), given ``--ros-args`` with its parameter files and
remappings. All nodes of a graph share one ``ROS_DOMAIN_ID`` with discovery kept on this host.

- :meth:`Supervisor.start` starts every node and waits until each is present in the ROS graph
  (graph introspection from a private context in the same domain; a timeout names the
  missing nodes).
- :meth:`Supervisor.check` raises :class:`NodeDied` naming a node that exited with a code
  outside its spec's ``end_codes`` (default: only 0), with the exit code, its last error line
  and last log lines. A process that exits with one of its ``end_codes`` has *ended*, not
  died (docs/graph.md, "Lifecycle and bad input"); it is no longer waited for in the graph,
  and :meth:`Supervisor.ended` lists it.
- :meth:`Supervisor.stop` sends SIGINT, then SIGTERM and SIGKILL after timeouts, to every
  process group, in stages: a spec's ``stop_stage`` orders them (the recorder stops after
  the nodes it records). Children also get ``PR_SET_PDEATHSIG`` so none outlives a killed
  supervisor.

Every node gets the Fast DDS profiles of ``fourws_bringup/config/fastdds_profiles.xml``
(:func:`dds_environment`, unless the environment names a profiles file of its own: more
participant announcements, a 100 ms heartbeat for reliable writers) and
``FOURWS_FAST_EXIT=1``: it ends with ``os._exit`` once its clean-up is done
(:mod:`fourws_common.node_main`; docs/graph.md, "Timing").
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import json
import os
import random
import signal
import subprocess
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import yaml

DOMAIN_LOCK_DIR = Path(os.environ.get("FOURWS_DOMAIN_LOCK_DIR", "/tmp"))
DOMAIN_RANGE = range(1, 101)
#: The variable through which Fast DDS 2.x (Jazzy's) finds a profiles file; a user's
#: profiles file under either name (3.x reads the second) is kept.
DDS_PROFILES_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"
USER_PROFILES_ENV = (DDS_PROFILES_ENV, "FASTDDS_DEFAULT_PROFILES_FILE")
DDS_PROFILES_FILE = "fastdds_profiles.xml"


def dds_environment(environ: dict[str, str] | None = None) -> dict[str, str]:
    """The variables that give the nodes fourws's Fast DDS profiles (module docstring):
    none when ``environ`` (default ``os.environ``) names a profiles file already (the user's
    own wins) or the file cannot be found."""
    environ = os.environ if environ is None else environ
    if any(environ.get(k) for k in USER_PROFILES_ENV):
        return {}
    try:
        from fourws_common.resources import config_dir

        path = config_dir("fourws_bringup") / DDS_PROFILES_FILE
    except Exception:  # noqa: BLE001 - no installed share: the middleware's defaults
        return {}
    return {DDS_PROFILES_ENV: str(path)} if path.is_file() else {}



class SupervisorError(RuntimeError):
    """A graph could not be started or kept alive."""


class NodeDied(SupervisorError):
    """A supervised node exited while the graph was running."""

    def __init__(self, name: str, returncode: int, last_lines: list[str]) -> None:
        from fourws_common.exit_codes import describe

        self.name = name
        self.returncode = returncode
        self.last_lines = last_lines
        self.last_error = last_error_line(last_lines)
        tail = "\n".join("    " + line for line in last_lines)
        why = f": {self.last_error}" if self.last_error else ""
        super().__init__(f"node '{name}' died with exit code {describe(returncode)}{why}; "
                         f"last log lines:\n{tail}")


_ERROR_MARKS = ("[fatal]", "FATAL", "[ERROR]", "Error:", "Exception:", "Traceback")


def last_error_line(lines: list[str]) -> str:
    """The last log line that reports an error (a ROS ERROR/FATAL line, ``[fatal]``, a Python
    exception line), else ``""``."""
    for line in reversed(lines):
        if any(m in line for m in _ERROR_MARKS):
            return line.strip()
    return ""


class GraphTimeout(SupervisorError):
    """Some nodes never appeared in the ROS graph."""

    def __init__(self, missing: list[str], timeout_s: float) -> None:
        self.missing = missing
        super().__init__(
            f"node(s) {', '.join(missing)} did not appear in the ROS graph within {timeout_s:.0f} s"
        )


@dataclass
class NodeSpec:
    """One node to start: ``ros2 run package executable --ros-args ...``."""

    name: str
    package: str
    executable: str
    params_files: list[str] = field(default_factory=list)
    parameters: dict[str, object] = field(default_factory=dict)
    remappings: dict[str, str] = field(default_factory=dict)
    extra_args: list[str] = field(default_factory=list)
    log_level: str = "info"
    argv: list[str] | None = None  # a program to run instead of lib/<package>/<executable>
    nice: int = 0  # added to the process's niceness (0..19): lower CPU priority
    # Graph names of the nodes a container process hosts (empty: one node named ``name``).
    # A container keeps its nodes' own names; ``parameters`` keys are then ``node:param``.
    hosts: tuple[str, ...] = ()
    # Exit codes that end this process normally (not a death); the plant's include the
    # run's outcomes (fourws_common.exit_codes.RUN_END_CODES).
    end_codes: frozenset[int] = frozenset({0})
    # ROS namespace of the process's nodes ("" or "/": the root); their relative topics move
    # with it (``-r __ns:=/car1``)
    namespace: str = ""
    # Order of stopping: every process of a lower stage has exited before this one gets
    # SIGINT (a recorder is 1: it outlives the writers it records).
    stop_stage: int = 0

    def __post_init__(self) -> None:
        if not 0 <= self.nice <= 19:
            raise ValueError(f"{self.name}: nice must be in 0..19, got {self.nice}")
        self.namespace = normalise_namespace(self.namespace)

    @property
    def graph_names(self) -> tuple[str, ...]:
        """The node names this process puts in the ROS graph."""
        return self.hosts or (self.name,)

    @property
    def qualified_names(self) -> tuple[str, ...]:
        """The fully qualified names of :attr:`graph_names` (``/car1/mpc_node``)."""
        return tuple(f"{self.namespace.rstrip('/')}/{n}" for n in self.graph_names)

    @classmethod
    def compose(cls, name: str, specs: list[NodeSpec]) -> NodeSpec:
        """One ``fourws_bringup/container`` process hosting the nodes of ``specs``.

        Parameter files are passed once each (their sections are keyed by node name), in an
        order that keeps every spec's own order, since a later file overrides an earlier one
        (``allocator.yaml`` then the controller preset); each spec's ``parameters`` become
        node-qualified (``-p allocator_node:sync:=lockstep``). So every node gets exactly the
        parameters it would get in a process of its own; ValueError if no single order can.
        """
        if not specs:
            raise ValueError(f"{name}: a container needs at least one node")
        bad = [s.name for s in specs if s.hosts or s.argv or s.extra_args
               or s.remappings != specs[0].remappings]
        if bad:
            raise ValueError(f"{name}: cannot host {bad} (containers, custom programs, "
                             "extra arguments and remappings not shared by every hosted node "
                             "stay processes of their own)")
        spaces = {s.namespace for s in specs}
        if len(spaces) > 1:
            raise ValueError(f"{name}: one container has one namespace, got {sorted(spaces)}")
        files = _merge_orders([s.params_files for s in specs], name)
        params = {f"{s.name}:{k}": v for s in specs for k, v in s.parameters.items()}
        return cls(name, "fourws_bringup", "container", params_files=files, parameters=params,
                   log_level=specs[0].log_level, nice=min(s.nice for s in specs),
                   hosts=tuple(s.name for s in specs),
                   end_codes=frozenset().union(*(s.end_codes for s in specs)),
                   namespace=specs[0].namespace, remappings=dict(specs[0].remappings))

    def program_arguments(self) -> list[str]:
        """The arguments before ``--ros-args``: a container's ``--nodes`` list."""
        return ["--nodes", ",".join(self.hosts)] if self.hosts else []

    def ros_arguments(self) -> list[str]:
        """What follows ``--ros-args`` but the node name and namespace: log level,
        parameter files, parameters (``-p``) and remappings, in that order."""
        out = ["--log-level", self.log_level]
        for f in self.params_files:
            out += ["--params-file", str(f)]
        for k, v in self.parameters.items():
            out += ["-p", f"{k}:={_param_literal(v)}"]
        for src, dst in self.remappings.items():
            out += ["-r", f"{src}:={dst}"]
        return out

    def command(self) -> list[str]:
        program = self.argv or [str(executable_path(self.package, self.executable))]
        cmd = [*program, *self.program_arguments(), "--ros-args"]
        if not self.hosts:
            cmd += ["-r", f"__node:={self.name}"]
        if self.namespace != "/":
            cmd += ["-r", f"__ns:={self.namespace}"]
        return cmd + self.ros_arguments() + list(self.extra_args)


def normalise_namespace(ns: str) -> str:
    """``car1``, ``/car1/`` -> ``/car1``; ``""`` -> ``/``. ValueError for a name ROS rejects
    (each token a letter or underscore, then letters, digits, underscores)."""
    import re

    ns = "/" + ns.strip().strip("/")
    if ns != "/" and not re.fullmatch(r"(/[A-Za-z_][A-Za-z0-9_]*)+", ns):
        raise ValueError(f"namespace {ns!r}: tokens must start with a letter or underscore "
                         "and hold letters, digits and underscores only")
    return ns


def _merge_orders(orders: list[list[str]], what: str) -> list[str]:
    """One list holding every item once, each input's order kept (a topological sort, ties
    broken by first appearance); ValueError naming ``what`` if the orders contradict."""
    items = list(dict.fromkeys(x for order in orders for x in order))
    after: dict[str, set[str]] = {x: set() for x in items}  # x → items that must precede x
    for order in orders:
        for i, x in enumerate(order):
            after[x].update(y for y in order[:i] if y != x)
    out: list[str] = []
    while len(out) < len(items):
        ready = [x for x in items if x not in out and after[x] <= set(out)]
        if not ready:
            raise ValueError(f"{what}: the parameter files' orders contradict each other: "
                             f"{orders}")
        out.append(ready[0])
    return out


def _param_literal(v: object) -> str:
    """``v`` as the YAML value of ``-p name:=value``. A string is passed as written (so
    ``"[/a,/b]"`` stays a YAML list, as on a ``ros2 run`` command line), except one that YAML
    reads as a mapping (``{a: 1}``): no parameter can hold a mapping, so such a string is
    meant as text (``vehicle_overrides``) and is double-quoted to stay one."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        try:
            mapping = isinstance(yaml.safe_load(v), dict)
        except yaml.YAMLError:
            mapping = False
        return json.dumps(v) if mapping else v
    return repr(v)


def executable_path(package: str, executable: str) -> Path:
    """Where ``ros2 run`` would find the executable: ``<prefix>/lib/<package>/<executable>``."""
    from ament_index_python.packages import get_package_prefix

    path = Path(get_package_prefix(package)) / "lib" / package / executable
    if not path.exists():
        raise SupervisorError(f"executable not found: {path} (is the workspace built?)")
    return path


class DomainLease:
    """An exclusive ``ROS_DOMAIN_ID`` for this process, held by a lock file until released."""

    def __init__(self, preferred: int | None = None) -> None:
        candidates = list(DOMAIN_RANGE)
        random.Random(os.getpid() ^ time.monotonic_ns()).shuffle(candidates)
        if preferred is not None:
            candidates.insert(0, preferred)
        for did in candidates:
            fh = open(DOMAIN_LOCK_DIR / f"fourws-domain-{did}.lock", "w")  # noqa: SIM115
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                fh.close()
                continue
            self.domain_id = did
            self._fh = fh
            return
        raise SupervisorError("no free ROS_DOMAIN_ID in 1..100")

    def release(self) -> None:
        if self._fh is not None:
            fcntl.flock(self._fh, fcntl.LOCK_UN)
            self._fh.close()
            self._fh = None


def _set_pdeathsig() -> None:
    with contextlib.suppress(Exception):
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


class _Proc:
    def __init__(self, spec: NodeSpec, popen: subprocess.Popen, log_path: Path) -> None:
        self.spec = spec
        self.popen = popen
        self.log_path = log_path

    def last_lines(self, n: int = 15) -> list[str]:
        try:
            with open(self.log_path, encoding="utf-8", errors="replace") as fh:
                return [line.rstrip("\n") for line in deque(fh, maxlen=n)]
        except OSError:
            return []


class Supervisor:
    """Start, watch and stop a list of nodes in one ROS domain on this host."""

    def __init__(self, specs: list[NodeSpec], domain_id: int, log_dir: str | Path,
                 env: dict[str, str] | None = None) -> None:
        names = [s.name for s in specs]
        if len(set(names)) != len(names):
            raise SupervisorError(f"node names must be unique: {names}")
        self.specs = specs
        self.domain_id = domain_id
        self.log_dir = Path(log_dir)
        self.env = dict(os.environ)
        self.env.update(env or {})
        self.env.update(dds_environment(self.env))
        self.env["ROS_DOMAIN_ID"] = str(domain_id)
        self.env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        self.env["PYTHONUNBUFFERED"] = "1"
        # os._exit once a node's clean-up is done (fourws_common.node_main, "Exit")
        self.env.setdefault("FOURWS_FAST_EXIT", "1")
        self.env.setdefault("RCUTILS_LOGGING_BUFFERED_STREAM", "0")
        self.procs: dict[str, _Proc] = {}
        self._ctx = None
        self._probe = None

    # -- lifecycle -------------------------------------------------------------------------
    def start(self, timeout_s: float = 30.0) -> None:
        """Start every node and wait until all are in the ROS graph."""
        self.log_dir.mkdir(parents=True, exist_ok=True)
        try:
            for spec in self.specs:
                self._spawn(spec)
            self.wait_for_graph([n for s in self.specs for n in s.qualified_names], timeout_s)
        except BaseException:
            self.stop()
            raise

    def _spawn(self, spec: NodeSpec) -> None:
        log_path = self.log_dir / f"{spec.name}.log"
        fh = open(log_path, "w", encoding="utf-8")  # noqa: SIM115
        nice = spec.nice

        def preexec() -> None:
            _set_pdeathsig()
            if nice:
                os.nice(nice)

        popen = subprocess.Popen(  # noqa: S603
            spec.command(), stdout=fh, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            env=self.env, start_new_session=True, preexec_fn=preexec,
        )
        fh.close()
        self.procs[spec.name] = _Proc(spec, popen, log_path)

    def _graph_probe(self):
        if self._probe is None:
            import rclpy

            self._ctx = rclpy.Context()
            rclpy.init(context=self._ctx, domain_id=self.domain_id)
            self._probe = rclpy.create_node(
                f"fourws_supervisor_{os.getpid()}", context=self._ctx,
                start_parameter_services=False, enable_rosout=False,
            )
        return self._probe

    def wait_for_graph(self, names: list[str], timeout_s: float) -> None:
        """Poll graph introspection until every fully qualified node name (``/ns/node``) is
        present; raise naming the missing.

        A process that has already ended normally (a short run can start, finish and exit
        before the probe sees it) is not waited for; one that died raises :class:`NodeDied`.
        """
        probe = self._graph_probe()
        deadline = time.monotonic() + timeout_s
        missing = list(names)
        while True:
            self.check()
            gone = {n for p in self.ended() for n in self.procs[p].spec.qualified_names}
            present = {f"{ns.rstrip('/')}/{n}"
                       for n, ns in probe.get_node_names_and_namespaces()} | gone
            missing = [n for n in names if n not in present]
            if not missing:
                return
            if time.monotonic() > deadline:
                raise GraphTimeout(missing, timeout_s)
            time.sleep(0.05)

    def check(self) -> None:
        """Raise :class:`NodeDied` if a process has exited with a code outside its
        ``end_codes``; a normal end (:meth:`ended`) is not a death."""
        for name, proc in self.procs.items():
            rc = proc.popen.poll()
            if rc is not None and rc not in proc.spec.end_codes:
                raise NodeDied(self.describe(name), rc, proc.last_lines())

    def ended(self) -> dict[str, int]:
        """Processes that have ended normally (an exit code in their ``end_codes``)."""
        return {n: rc for n, rc in self.exited().items() if rc in self.procs[n].spec.end_codes}

    def describe(self, name: str) -> str:
        """A process's name, with the nodes it hosts if it is a container."""
        hosted = self.procs[name].spec.hosts
        return f"{name} ({', '.join(hosted)})" if hosted else name

    def exited(self) -> dict[str, int]:
        """Nodes that have exited, with their exit codes."""
        return {n: p.popen.returncode for n, p in self.procs.items() if p.popen.poll() is not None}

    def wait_exit(self, name: str, timeout_s: float | None = None) -> int:
        """Wait for one node to exit by itself (e.g. the plant at the end of a scenario)."""
        return self.procs[name].popen.wait(timeout=timeout_s)

    def stop(self, sigint_timeout_s: float = 5.0, sigterm_timeout_s: float = 3.0) -> dict[str, int]:
        """Stop every node, stage by stage (``NodeSpec.stop_stage``, lowest first): SIGINT,
        then SIGTERM, then SIGKILL. Returns the exit codes."""
        for stage in sorted({p.spec.stop_stage for p in self.procs.values()}):
            self._stop_group([p for p in self.procs.values() if p.spec.stop_stage == stage],
                             sigint_timeout_s, sigterm_timeout_s)
        # Reap stragglers left in a node's process group (e.g. grandchildren).
        for p in self.procs.values():
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(p.popen.pid, signal.SIGKILL)
        self._close_probe()
        return {n: p.popen.returncode for n, p in self.procs.items()}

    @staticmethod
    def _stop_group(procs: list, sigint_timeout_s: float, sigterm_timeout_s: float) -> None:
        for sig, timeout in ((signal.SIGINT, sigint_timeout_s),
                             (signal.SIGTERM, sigterm_timeout_s), (signal.SIGKILL, 5.0)):
            alive = [p for p in procs if p.popen.poll() is None]
            if not alive:
                break
            for p in alive:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(p.popen.pid, sig)
            deadline = time.monotonic() + timeout
            for p in alive:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    p.popen.wait(timeout=max(0.0, deadline - time.monotonic()))

    def _close_probe(self) -> None:
        if self._probe is not None:
            import rclpy

            self._probe.destroy_node()
            rclpy.try_shutdown(context=self._ctx)
            self._probe = None
            self._ctx = None

    def pids(self) -> list[int]:
        return [p.popen.pid for p in self.procs.values()]

    def __enter__(self) -> Supervisor:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
