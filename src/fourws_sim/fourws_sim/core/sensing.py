"""Models a realistic bench's sensing and timing: seeded measurement noise and command delays.

Measurement error per channel (what the controllers receive instead of the plant's state;
docs/plant.md, "Sensing and localisation"):

* white: n_k ~ N(0, σ²), independent per sample;
* first-order Gauss-Markov with correlation time τ (a slowly wandering localisation error),
  sampled exactly at the period T::

      n_{k+1} = φ n_k + σ √(1 − φ²) w_k,   φ = exp(−T/τ),   w_k ~ N(0, 1)

  started from its stationary distribution N(0, σ²), so the error has variance σ² and the
  autocorrelation exp(−|Δt|/τ) from the first sample on.

Each channel draws from its own generator seeded from (seed, channel name), so adding a channel
leaves the others' sequences unchanged and a seed reproduces a run bit for bit.

Timing: :class:`DelayLine` holds a command for N periods (a command computed from the state of
step k acts from step k + N: computation delay), and :class:`DeadTime` holds the steering
command for a dead time in substeps on top of the actuator's own lag and rate limits.
"""

from __future__ import annotations

import copy
import math
import zlib
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fourws_sim.core.localisation import pose_filter

#: the measured channels noise can act on (VehicleState field names)
CHANNELS = ("x", "y", "yaw", "vx", "vy", "yaw_rate", "ax", "ay")


@dataclass(frozen=True)
class NoiseSpec:
    """σ (SI units of the channel) and τ (s; 0 = white) of one channel."""

    sigma: float = 0.0
    tau_s: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sigma) and self.sigma >= 0.0):
            raise ValueError(f"noise sigma: expected a finite value >= 0, got {self.sigma!r}")
        if not (math.isfinite(self.tau_s) and self.tau_s >= 0.0):
            raise ValueError(f"noise tau_s: expected a finite value >= 0, got {self.tau_s!r}")


#: the largest noise seed: a stream takes 32 bits of it
MAX_SEED = 2**32 - 1


def _channel_seed(seed: int, name: str) -> np.random.SeedSequence:
    return np.random.SeedSequence([int(seed) & MAX_SEED, zlib.crc32(name.encode())])


class NoiseChannel:
    """One seeded noise sequence (module docstring)."""

    def __init__(self, spec: NoiseSpec, dt_s: float, seed: int, name: str) -> None:
        if not dt_s > 0.0:
            raise ValueError(f"dt_s: expected > 0, got {dt_s!r}")
        self.spec = spec
        self._rng = np.random.default_rng(_channel_seed(seed, name))
        self._phi = math.exp(-dt_s / spec.tau_s) if spec.tau_s > 0.0 else 0.0
        self._gain = spec.sigma * math.sqrt(1.0 - self._phi * self._phi)
        self._n: float | None = None

    def sample(self) -> float:
        """The error of the next sample."""
        w = float(self._rng.standard_normal())
        if self._n is None or self._phi == 0.0:
            self._n = self.spec.sigma * w          # stationary start; white every sample
        else:
            self._n = self._phi * self._n + self._gain * w
        return self._n


@dataclass
class MeasurementNoise:
    """Noise on the listed channels of a state (an object with those attributes)."""

    specs: Mapping[str, NoiseSpec]
    dt_s: float
    seed: int = 0
    _channels: dict[str, NoiseChannel] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        unknown = sorted(set(self.specs) - set(CHANNELS))
        if unknown:
            raise ValueError(f"noise: unknown channel(s) {unknown} (known: {', '.join(CHANNELS)})")
        self._channels = {name: NoiseChannel(spec, self.dt_s, self.seed, name)
                          for name, spec in self.specs.items() if spec.sigma > 0.0}

    @property
    def active(self) -> bool:
        """Some channel has noise (σ > 0)."""
        return bool(self._channels)

    def errors(self) -> dict[str, float]:
        """The next error of every noisy channel (name -> value)."""
        return {name: ch.sample() for name, ch in self._channels.items()}

    def apply(self, state: Any) -> dict[str, float]:
        """Add the next errors to ``state``'s attributes in place; returns the errors."""
        errs = self.errors()
        for name, e in errs.items():
            setattr(state, name, getattr(state, name) + e)
        return errs


def noise_specs(d: Mapping[str, Any] | None) -> dict[str, NoiseSpec]:
    """From a YAML mapping ``{channel: {sigma: s, tau_s: t}}`` (SI units)."""
    specs: dict[str, NoiseSpec] = {}
    for name, v in (d or {}).items():
        if not isinstance(v, Mapping) or set(v) - {"sigma", "tau_s"}:
            raise ValueError(f"noise.{name}: expected {{sigma: ..., tau_s: ...}}, got {v!r}")
        specs[str(name)] = NoiseSpec(float(v.get("sigma", 0.0)), float(v.get("tau_s", 0.0)))
    return specs


def noise_from_mapping(d: Mapping[str, Any] | None, dt_s: float, seed: int
                       ) -> MeasurementNoise:
    """:class:`MeasurementNoise` of :func:`noise_specs`."""
    return MeasurementNoise(noise_specs(d), dt_s, seed)


class DelayLine:
    """Holds values for ``periods`` pushes: ``push(v)`` returns the value pushed ``periods``
    calls before (``initial`` until then). ``periods = 0`` passes every value through."""

    def __init__(self, periods: int, initial: Any) -> None:
        if periods < 0:
            raise ValueError(f"delay periods: expected >= 0, got {periods}")
        self._q: deque = deque([initial] * periods)

    def push(self, value: Any) -> Any:
        self._q.append(value)
        return self._q.popleft()


class DeadTime:
    """A pure dead time in substeps for the steering command: :meth:`at` gives the command
    that acts in substep ``i`` (counted from the start of the run) when a new command arrives
    at substep ``i_new``; before the first command has passed the dead time, ``initial``."""

    def __init__(self, substeps: int, initial: tuple[float, float]) -> None:
        if substeps < 0:
            raise ValueError(f"dead time substeps: expected >= 0, got {substeps}")
        self.substeps = substeps
        self._pending: deque[tuple[int, tuple[float, float]]] = deque()
        self._active = initial

    def command(self, i_now: int, cmd: tuple[float, float]) -> None:
        """A command issued at substep ``i_now``."""
        self._pending.append((i_now + self.substeps, cmd))

    def at(self, i: int) -> tuple[float, float]:
        """The command acting in substep ``i``."""
        while self._pending and self._pending[0][0] <= i:
            self._active = self._pending.popleft()[1]
        return self._active


#: where the controllers' tyre data come from: the plant's truth (the paper's idealised
#: setting) or an estimate from measured accelerations (no plant truth)
TYRE_SOURCES = ("oracle", "estimated")
#: the VehicleState fields no car measures: zero in a sensed state without the oracle
UNMEASURED_WHEEL_FIELDS = ("fx", "fy", "fz", "mu")


class Sensors:
    """What a car's sensors give its controllers, and when their commands act: the one
    statement of a realistic bench's plant side, used by the plant node and the in-process
    loop alike (so the graph reproduces the in-process run for a seed).

    :meth:`measure` turns the plant's outputs of a new step into the state the controllers
    receive: the noise of :class:`MeasurementNoise` on the measured channels (one draw per
    step: call it once per new state, never for a repeat), with ``localisation: ekf`` the
    pose of a localisation filter that knows those errors' models
    (``fourws_sim.core.localisation``) in place of the raw fix, the sideslip β = atan2(v_y, v_x)
    of the measured velocities, and — unless ``tyre_forces`` is ``oracle`` — zero in the
    fields no car measures (:data:`UNMEASURED_WHEEL_FIELDS`: tyre forces, loads, adhesion).
    :meth:`act` is the computation delay (:class:`DelayLine`) on the commands. With no noise,
    the oracle and no delay (``ideal``) both pass their input through untouched.
    """

    def __init__(self, noise: Mapping[str, NoiseSpec] | None, dt_s: float, seed: int = 0,
                 delay_periods: int = 0, tyre_forces: str = "oracle",
                 initial_command: Any = None, localisation: str = "none") -> None:
        if tyre_forces not in TYRE_SOURCES:
            raise ValueError(f"tyre_forces: '{tyre_forces}' is not one of {TYRE_SOURCES}")
        self.noise = MeasurementNoise(dict(noise or {}), dt_s, seed)
        self.tyre_forces = tyre_forces
        self.delay = DelayLine(delay_periods, initial_command)
        self.localiser = pose_filter(localisation, dict(noise or {}), dt_s)
        self.sensed = (self.noise.active or tyre_forces != "oracle"
                       or self.localiser is not None)
        self.ideal = not self.sensed and delay_periods == 0

    def measure(self, out: Any) -> Any:
        """The measured state of the plant's outputs ``out`` (a copy when sensed)."""
        if not self.sensed:
            return out
        seen = copy.copy(out)               # shallow, as dataclasses.replace, without __init__
        noisy = bool(self.noise.apply(seen))
        if self.localiser is not None:
            noisy = self.localiser.apply(seen) or noisy
        if noisy:
            seen.sideslip = math.atan2(seen.vy, seen.vx)
        if self.tyre_forces != "oracle":
            for name in UNMEASURED_WHEEL_FIELDS:
                setattr(seen, name, np.zeros(np.shape(getattr(out, name))))
        return seen

    def act(self, cmd: Any) -> Any:
        """The command that acts now: the one pushed ``delay_periods`` steps ago
        (``initial_command`` until then). Pass the controllers' output every step."""
        return cmd if self.ideal else self.delay.push(cmd)


def sensors_from_params(values: Mapping[str, Any], dt_s: float,
                        initial_command: Any = None) -> Sensors:
    """:class:`Sensors` of the plant's parameters (``plant_node``'s ``noise_sigma`` and
    ``noise_tau_s``, one value per channel of :data:`CHANNELS` in order; ``noise_seed``,
    ``delay_periods``, ``tyre_forces``, ``localisation``): the plant node and the in-process
    loop build their bench from the same values."""
    sigma = tuple(values.get("noise_sigma") or (0.0,) * len(CHANNELS))
    tau = tuple(values.get("noise_tau_s") or (0.0,) * len(CHANNELS))
    if len(sigma) != len(CHANNELS) or len(tau) != len(CHANNELS):
        raise ValueError(f"noise_sigma, noise_tau_s: one value per channel {CHANNELS}, got "
                         f"{len(sigma)} and {len(tau)}")
    noise = {ch: NoiseSpec(float(s), float(t))
             for ch, s, t in zip(CHANNELS, sigma, tau, strict=True) if float(s) > 0.0}
    return Sensors(noise, dt_s, int(values.get("noise_seed", 0)),
                   int(values.get("delay_periods", 0)),
                   str(values.get("tyre_forces", "oracle")), initial_command,
                   str(values.get("localisation", "none")))
