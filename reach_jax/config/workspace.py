"""Whether a visual field lies where the arm reaches every point inside its joint limits (model §2); [m], [rad].

Plain math on the config's numbers, so that a config is checked before anything is built: training places starts and
targets anywhere in the field, and the test lattice's points lie in it, so every point of the field must be reachable
with the elbow in (theta2_min, theta2_stop) and the shoulder inside theta1_range.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

from reach_jax.config.schema import ArmConfig, Config, SensorConfig

GEOMETRY_HYPERS = ("sensor_dx", "sensor_dy", "sensor_scale")  # the hyperparameters that place a learner's field
POINTS_PER_SIDE = 41  # the field is checked on this grid, edges and corners included (1/40 of its side apart)


def moved_sensor(sensor: SensorConfig, dx: float, dy: float, scale: float) -> SensorConfig:
    """`sensor` moved by (dx, dy) [m] and its cell scaled by `scale` (hyper sensor_dx, sensor_dy, sensor_scale)."""
    return dataclasses.replace(
        sensor, centre=(sensor.centre[0] + dx, sensor.centre[1] + dy), cell_size=sensor.cell_size * scale
    )


def sweep_sensors(cfg: Config) -> list[SensorConfig]:
    """The sensor of every sweep point of cfg.train, crossed or zipped as the sweep grids are (`engine.batch`)."""
    t, learner = cfg.train, cfg.learner
    names = ("sensor_dx", "sensor_dy", "sensor_scale")
    grids = [getattr(t, f"{n}_grid") or (getattr(learner, n),) for n in names]
    if t.zip_grids:
        n = max(len(g) for g in grids)
        points = zip(*(g * (n // len(g)) for g in grids), strict=True)
    else:
        points = itertools.product(*grids)
    return list(dict.fromkeys(moved_sensor(cfg.sensor, *p) for p in points))


def joint_angles(x: float, y: float, arm: ArmConfig) -> tuple[float, float] | None:
    """(theta1, theta2) [rad] of the hand at (x, y) [m] with theta2 in [0, pi]; None out of reach (`arm`'s IK)."""
    l1, l2 = arm.length
    c2 = (x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    if not -1.0 <= c2 <= 1.0:
        return None
    theta2 = math.acos(c2)
    return math.atan2(y, x) - math.atan2(l2 * math.sin(theta2), l1 + l2 * c2), theta2


def field_fault(sensor: SensorConfig, arm: ArmConfig) -> str | None:
    """Why the visual field of `sensor` is no place to reach in, in words, or None where every point of it is fine."""
    half = 0.5 * sensor.n_cells * sensor.cell_size
    ks = [i / (POINTS_PER_SIDE - 1) for i in range(POINTS_PER_SIDE)]
    for ky in ks:
        for kx in ks:
            x, y = sensor.centre[0] - half + 2 * half * kx, sensor.centre[1] - half + 2 * half * ky
            angles = joint_angles(x, y, arm)
            where = f"its point ({x:.3f}, {y:.3f}) m"
            if angles is None:
                return f"{where} is out of the arm's reach"
            theta1, theta2 = angles
            lo, hi = arm.theta1_range
            if not lo < theta1 < hi:
                return f"{where} needs a shoulder angle of {math.degrees(theta1):.1f} deg, outside its joint limits"
            if not arm.theta2_min < theta2 < arm.theta2_stop:
                return f"{where} needs an elbow angle of {math.degrees(theta2):.1f} deg, outside its joint limits"
    return None
