"""Imperfect sensing: a limited field of view and range, noise, dropouts and occlusion.

The paper's robot senses every object perfectly (bearing) or with a panoramic camera
(visibility); its §5.1 names noise and missing observations as the open problem. Real cameras
are narrower: the MRCLAM robots' see about 60 degrees. :class:`SensingLimits` takes the perfect
reading of one step and returns what an imperfect sensor reports, plus which objects it
reported on (``observed``), so that the histories carry a mask (:attr:`History.mask`) and the
masked mapping methods know which entries are measurements.

Every limit is off by default; with all of them off the environment never builds this class
and its observations are exactly the paper's. Random draws come from the class's own
generator, seeded from the episode's reset seed, never from the environment's ``np_random``,
so noise and dropouts never change the layout, the start pose or the robot's path.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

import lfmdr_gym.sim.sensors as sensors
from lfmdr_gym.checks import check_real
from mappers.core.sensors import sensors_of

__all__ = ["LIMIT_DEFAULTS", "SensingLimits"]

LIMIT_DEFAULTS: dict[str, Any] = {
    "fov_deg": 360.0,
    "max_range": None,
    "bearing_noise_deg": 0.0,
    "range_noise": 0.0,
    "miss_rate": 0.0,
    "false_rate": 0.0,
    "line_of_sight": False,
}
"""Each limit's value when it is off (the environment's keyword defaults)."""

# Which sensor a sensor-specific limit applies to (the others apply to every sensor). A limit
# given for another sensor is refused rather than ignored.
_ONLY_FOR = {
    "bearing_noise_deg": ("bearing",),
    "range_noise": ("range",),
    "miss_rate": ("visibility",),
    "false_rate": ("visibility",),
    "line_of_sight": ("bearing", "range"),
}

# A tag mixed into the reset seed: the noise stream is independent of the env's np_random.
_STREAM_TAG = 0x6E6F6973


class SensingLimits:
    """Turns one step's perfect reading into an imperfect sensor's (see the module docstring).

    Args:
        sensor: ``"visibility"``, ``"bearing"`` or ``"range"``, or a fused set of them
            (``"range-bearing"``, ``"visibility-bearing"``): then one camera senses every sensor
            of the set, so the field of view, range and line of sight give one ``observed`` for
            all, and each sensor's own limits (noise, dropouts) apply to its reading only, drawn
            independently (:meth:`apply`).
        n_objects: M.
        object_radius: r [m], for ``line_of_sight``.
        fov_deg: field of view in degrees, centred on the heading, in (0, 360]: object j is
            observed only if its centre's bearing ``theta_j`` obeys ``|theta_j| <= fov_deg / 2``.
        max_range: [m] centre to centre, or None: object j is observed only if ``d_j <= max_range``.
        bearing_noise_deg: standard deviation [deg] of Gaussian noise added to each bearing angle.
        range_noise: standard deviation [m] of Gaussian noise added to each range; a noisy
            range is clipped to ``[0, range_high]`` (the observation space), which at the
            bound of 10 standard deviations past the largest true range never happens in practice
            and at 0 keeps the reading a distance.
        miss_rate: probability that a visible object is reported not visible.
        false_rate: probability that an object inside the view and range that is not visible
            (too far to see, or occluded) is reported visible.
        line_of_sight: occlusion for bearing and range: an object is observed only if the
            segment from the robot's centre to its centre passes no nearer than r to another
            object's centre (the visibility sensor's ``occlusion`` test).
        range_high: the range observation's upper bound without noise (for the clip).

    ``observed`` (int8, M) is 1 for the objects the sensor reported on this step: inside the
    field of view and range, and (``line_of_sight``) not hidden. Entries not observed read 0.
    For visibility an observed entry may read 0 (too small to see, occluded, or missed) and,
    with ``false_rate``, 1 for an object that is not there to see: ``observed`` says where the
    camera looked, not what it saw.
    """

    def __init__(self, sensor: str, n_objects: int, object_radius: float, *,
                 range_high: float, **limits: Any) -> None:
        self.sensor = sensor
        self.sensors = sensors_of(sensor)
        self.n_objects = n_objects
        self.r2 = object_radius * object_radius
        self.fov = check_real("fov_deg", limits["fov_deg"], low=0.0, low_open=True, high=360.0)
        mr = limits["max_range"]
        self.max_range = None if mr is None else check_real("max_range", mr, low=0.0, low_open=True)
        self.bearing_noise = math.radians(check_real("bearing_noise_deg", limits["bearing_noise_deg"], low=0.0))
        self.range_noise = check_real("range_noise", limits["range_noise"], low=0.0)
        self.miss_rate = check_real("miss_rate", limits["miss_rate"], low=0.0, high=1.0, high_open=True)
        self.false_rate = check_real("false_rate", limits["false_rate"], low=0.0, high=1.0, high_open=True)
        los = limits["line_of_sight"]
        if not isinstance(los, bool | np.bool_):
            raise ValueError(f"line_of_sight must be True or False, got {los!r}")
        self.line_of_sight = bool(los)
        for name, for_sensors in _ONLY_FOR.items():
            if limits[name] != LIMIT_DEFAULTS[name] and not set(self.sensors) & set(for_sensors):
                raise ValueError(
                    f"{name} applies to the {' and '.join(for_sensors)} sensor(s), not to {sensor!r}"
                )
        self.half_fov = math.radians(self.fov) / 2.0
        self.range_high = range_high + 10.0 * self.range_noise
        self.rng: np.random.Generator | None = None

    @staticmethod
    def active(limits: dict[str, Any]) -> bool:
        """Whether any limit differs from its off value (:data:`LIMIT_DEFAULTS`)."""
        return any(limits[k] != v for k, v in LIMIT_DEFAULTS.items())

    def reset(self, seed: int | None) -> None:
        """Reseed the noise stream from the reset seed; without one, continue it (as ``np_random``)."""
        if seed is not None:
            self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), _STREAM_TAG]))
        elif self.rng is None:
            self.rng = np.random.default_rng()

    def observed(self, rel: np.ndarray, d2: np.ndarray, heading: float) -> np.ndarray:
        """(M,) bool: the objects inside the field of view and range and, with
        ``line_of_sight``, not hidden behind another object."""
        seen = np.ones(self.n_objects, dtype=bool)
        if self.fov < 360.0:
            c, s = math.cos(heading), math.sin(heading)
            theta = np.arctan2(c * rel[:, 1] - s * rel[:, 0], c * rel[:, 0] + s * rel[:, 1])
            seen &= np.abs(theta) <= self.half_fov
        if self.max_range is not None:
            seen &= np.sqrt(d2) <= self.max_range
        if self.line_of_sight:
            # The visibility test with targets within max_range (if any). An occluder of a
            # target at distance d lies within sqrt(d^2 + r^2) (see sensors), so only objects
            # that near are candidates: the cost scales with the objects in range, not with M.
            if self.max_range is None:
                cand, reach2 = np.arange(self.n_objects), math.inf
            else:
                reach2 = self.max_range * self.max_range
                cand = (d2 < reach2 + self.r2).nonzero()[0]
            dc2 = d2.take(cand)
            clear = sensors.visibility_kernel(self.n_objects, cand, rel.take(cand, axis=0), dc2,
                                              reach2, dc2 - self.r2, True)
            seen &= clear.astype(bool)
        return seen

    def apply(self, readings: dict[str, np.ndarray], rel: np.ndarray, d2: np.ndarray,
              heading: float) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Every sensor's imperfect reading (same shape and dtype as its perfect one; a fused
        set's noise drawn sensor after sensor, in :data:`SENSORS` order) and the one
        ``observed`` (int8) they share."""
        seen = self.observed(rel, d2, heading)
        out = {}
        for sensor in self.sensors:
            out[sensor] = self._perturb(sensor, readings[sensor])
            out[sensor][~seen] = 0
        return out, seen.astype(np.int8)

    def _perturb(self, sensor: str, reading: np.ndarray) -> np.ndarray:
        """``sensor``'s reading with its noise or dropouts (a copy)."""
        out = reading.copy()
        m = self.n_objects
        if sensor == "bearing" and self.bearing_noise > 0.0:
            theta = np.arctan2(out[:, 1], out[:, 0]) + self.rng.normal(0.0, self.bearing_noise, m)
            out = np.stack([np.cos(theta), np.sin(theta)], axis=1).astype(reading.dtype)
        elif sensor == "range" and self.range_noise > 0.0:
            noisy = out + self.rng.normal(0.0, self.range_noise, m)
            out = np.clip(noisy, 0.0, self.range_high).astype(reading.dtype)
        elif sensor == "visibility" and (self.miss_rate > 0.0 or self.false_rate > 0.0):
            u = self.rng.random(m)
            visible = out == 1
            out[visible & (u < self.miss_rate)] = 0
            out[~visible & (u < self.false_rate)] = 1
        return out
