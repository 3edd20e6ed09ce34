"""Sensor model of the testbed: irregular sample times, noise, quantisation, gaps and dropouts."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..._config import require

TIME_RESOLUTION_S = 1e-3  # time stamps are rounded to the millisecond
NOISE_FIELDS = ("temperature_noise_c", "temperature_quantum_c", "current_noise_a", "position_noise_rad",
                "velocity_noise_rad_s", "effort_noise_nm", "ambient_noise_c", "ambient_quantum_c", "voltage_noise_v")


@dataclass(frozen=True)
class SensorSettings:
    """How the simulated robot samples and corrupts its signals.

    Sample k is taken at (k + 1/2 + jitter_fraction * u_k) / sample_rate_hz, u_k ~ U(-1, 1),
    then rounded to the millisecond; samples inside a gap or hit by a dropout are deleted.
    Noise is Gaussian (standard deviations below); the temperature is noised, then quantised.
    """

    sample_rate_hz: float = 1.0
    jitter_fraction: float = 0.1
    temperature_noise_c: float = 0.1
    temperature_quantum_c: float = 0.1  # 0: no quantisation
    current_noise_a: float = 0.02
    position_noise_rad: float = 1e-4
    velocity_noise_rad_s: float = 5e-3
    effort_noise_nm: float = 0.2
    ambient_noise_c: float = 0.05
    ambient_quantum_c: float = 0.1
    voltage_noise_v: float = 0.05  # assumption: drive's voltage estimate, ~0.1 % of a 48 V bus (no dead-time error)
    gap_count: int = 0
    gap_duration_s: tuple[float, float] = (30.0, 300.0)
    dropout_probability: float = 0.0

    def __post_init__(self) -> None:
        src = "SensorSettings"
        require(0.001 <= self.sample_rate_hz <= 100, src, "sample_rate_hz", self.sample_rate_hz, "must be in [0.001, 100]")
        require(0 <= self.jitter_fraction < 0.5, src, "jitter_fraction", self.jitter_fraction, "must be in [0, 0.5)")
        for name in NOISE_FIELDS:
            value = getattr(self, name)
            require(math.isfinite(value) and value >= 0, src, name, value, "must be a finite number >= 0")
        require(isinstance(self.gap_count, int) and self.gap_count >= 0, src, "gap_count", self.gap_count,
                "must be an integer >= 0")
        low, high = self.gap_duration_s
        require(0 < low <= high, src, "gap_duration_s", self.gap_duration_s, "must be (low, high) with 0 < low <= high")
        require(0 <= self.dropout_probability < 0.5, src, "dropout_probability", self.dropout_probability,
                "must be in [0, 0.5)")

    @property
    def interval_bounds_s(self) -> tuple[float, float]:
        """Smallest and largest interval between consecutive samples when none is missing."""
        period = 1 / self.sample_rate_hz
        spread = 2 * self.jitter_fraction * period + TIME_RESOLUTION_S
        return period - spread, period + spread

    def noiseless(self) -> "SensorSettings":
        """Same sampling, no noise and no quantisation (for oracles)."""
        return dataclasses.replace(self, **{name: 0.0 for name in NOISE_FIELDS})


@dataclass(frozen=True)
class Sampling:
    """Sample times and what was cut out of the nominal grid."""

    time_s: np.ndarray
    gaps_s: tuple[tuple[float, float], ...]
    dropped: int


def sample_times(duration_s: float, settings: SensorSettings, rng: np.random.Generator) -> Sampling:
    """Jittered sample times in (0, duration_s), minus gaps and dropouts."""
    period = 1 / settings.sample_rate_hz
    count = int(math.floor(duration_s / period))
    require(count >= 2, "sample_times", "duration_s", duration_s, "shorter than two sample periods")
    k = np.arange(count)
    jitter = settings.jitter_fraction * rng.uniform(-1.0, 1.0, count)
    times = np.round((k + 0.5 + jitter) * period / TIME_RESOLUTION_S) * TIME_RESOLUTION_S
    gaps = _gaps(duration_s, settings, rng)
    keep = np.ones(count, dtype=bool)
    for start, end in gaps:
        keep &= ~((times > start) & (times < end))
    dropout = rng.uniform(size=count) < settings.dropout_probability
    dropout[[0, -1]] = False
    kept = keep & ~dropout
    return Sampling(times[kept], gaps, int(np.count_nonzero(keep & dropout)))


def _gaps(duration_s: float, settings: SensorSettings, rng: np.random.Generator) -> tuple[tuple[float, float], ...]:
    """Non-overlapping gaps, none touching the first or last tenth of the recording."""
    gaps: list[tuple[float, float]] = []
    for _ in range(settings.gap_count):
        length = rng.uniform(*settings.gap_duration_s)
        start = rng.uniform(0.1 * duration_s, 0.9 * duration_s - length) if 0.8 * duration_s > length else None
        if start is not None and all(start > e or start + length < s for s, e in gaps):
            gaps.append((float(start), float(start + length)))
    return tuple(sorted(gaps))


def quantise(values: np.ndarray, quantum: float) -> np.ndarray:
    """Round to the nearest multiple of ``quantum`` (no-op for quantum 0); clean decimals for CSV."""
    if quantum == 0:
        return np.asarray(values, float)
    return np.round(np.round(np.asarray(values, float) / quantum) * quantum, 10)


def measure(truth: dict[str, np.ndarray], settings: SensorSettings, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Noisy, quantised readings of the true signals (keys: contract column names)."""
    def noisy(name: str, sigma: float) -> np.ndarray:
        return truth[name] + sigma * rng.standard_normal(truth[name].shape)

    return {
        "current_a": noisy("current_a", settings.current_noise_a),
        "temperature_c": quantise(noisy("temperature_c", settings.temperature_noise_c), settings.temperature_quantum_c),
        "position": noisy("position", settings.position_noise_rad),
        "velocity": noisy("velocity", settings.velocity_noise_rad_s),
        "effort": noisy("effort", settings.effort_noise_nm),
        "ambient_c": quantise(noisy("ambient_c", settings.ambient_noise_c), settings.ambient_quantum_c),
        "voltage_v": noisy("voltage_v", settings.voltage_noise_v),
    }
