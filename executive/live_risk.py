"""Live risk: the checks a guard re-runs on every tick while a motion executes.

Two quantities, each against a limit of ``risk.guard`` (:class:`GuardConfig`):

* **predicted clearance**: the signed distance (coal, :class:`CollisionModel`) between
  the robot (with the object it carries) and the environment *as currently
  estimated*, at the robot's measured configuration and at the planned knots of
  the next ``lookahead_s`` seconds. An obstacle that the estimate says has moved
  into the path trips the guard before the hand gets there.
* **CoM margin**: the signed distance of the measured centre of mass inside the
  support polygon of the feet's *current contacts* (Long et al. 2018, eq. 3-4; the
  same polygon geometry as the fall model, :mod:`executive.polygon`).

The allowances are the planner's and the risk model's (a hand may touch the object
it grasps; a carried object its support while lifted or placed), so a planned
contact does not trip the guard.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.polygon import signed_margin
from executive.risk.collision import CollisionModel
from executive.risk.fall import support_polygon
from executive.scenario_types import GuardConfig
from executive.world import World

__all__ = ["GuardVerdict", "LiveRiskMonitor"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class GuardVerdict:
    """What one live check found. ``ok`` False names the limit crossed in ``reason``."""

    ok: bool
    reason: str
    min_distance: float  # least predicted robot-environment distance (m)
    at_s: float  # trajectory time of that distance (s)
    robot_body: str
    env_body: str
    com_margin: float | None  # m, None when not measured

    def as_dict(self) -> dict[str, object]:
        return {
            "ok": self.ok,
            "reason": self.reason,
            "min_distance": self.min_distance,
            "at_s": self.at_s,
            "robot_body": self.robot_body,
            "env_body": self.env_body,
            "com_margin": self.com_margin,
        }


class LiveRiskMonitor:
    """Guard checks on the estimate world (its obstacle and object poses are the current estimate).

    Not thread-safe (one collision model, one ``MjData``); the guards call it from the tick.
    """

    def __init__(
        self, estimate: World, config: GuardConfig, collision_model: CollisionModel | None = None
    ) -> None:
        self.world = estimate
        self.config = config
        self.collision = collision_model or CollisionModel(estimate, estimate.scenario.risk)
        self._object_qpos = [
            np.arange(adr, adr + 7) for adr in estimate.ids.object_qpos.values()
        ]  # free joints: 3 position + 4 quaternion

    def configuration(self, measured_qpos: FloatArray, planned_qpos: FloatArray) -> FloatArray:
        """The robot where it is measured, the objects where the plan has them (the estimate)."""
        q = np.array(measured_qpos, dtype=float, copy=True)
        for idx in self._object_qpos:
            q[idx] = planned_qpos[idx]
        return q

    def clearance(
        self,
        measured_qpos: FloatArray,
        trajectory_qpos: FloatArray,
        trajectory_times: FloatArray,
        t: float,
        *,
        carried: str | None,
        allow: frozenset[tuple[str, str]],
    ) -> tuple[float, float, str, str]:
        """Least distance now and at the planned knots in (t, t + lookahead]: (d, time, robot, env)."""
        times = np.asarray(trajectory_times, dtype=float)
        k_now = int(np.clip(np.searchsorted(times, t), 0, len(times) - 1))
        now = self.configuration(measured_qpos, trajectory_qpos[k_now])
        best = self.collision.knot(now, carried=carried, allow=allow)
        out = (best.distance, t, best.robot_body_name, best.env_body_name)
        ahead = np.nonzero((times > t) & (times <= t + self.config.lookahead_s))[0]
        for k in ahead:
            knot = self.collision.knot(trajectory_qpos[k], carried=carried, allow=allow)
            if knot.distance < out[0]:
                out = (knot.distance, float(times[k]), knot.robot_body_name, knot.env_body_name)
        return out

    def com_margin(self, world: World, data: mujoco.MjData) -> float | None:
        """Margin of the measured CoM in the polygon of the current foot contacts (None: no support).

        ``data`` must hold a stepped (or ``mj_forward``-ed) state: contacts and ``subtree_com``.
        """
        try:
            polygon = support_polygon(world, data, from_contacts=True)
        except ValueError:
            return None
        return float(signed_margin(polygon, data.subtree_com[world.ids.base_body][:2]))

    def check(
        self,
        measured_qpos: FloatArray,
        trajectory_qpos: FloatArray,
        trajectory_times: FloatArray,
        t: float,
        *,
        carried: str | None,
        allow: frozenset[tuple[str, str]],
        com_margin: float | None,
    ) -> GuardVerdict:
        """Both checks against the limits; the first limit crossed is the reason."""
        d, at, robot_body, env_body = self.clearance(
            measured_qpos, trajectory_qpos, trajectory_times, t, carried=carried, allow=allow
        )
        cfg = self.config
        reason = ""
        if d < cfg.min_distance:
            when = "now" if at <= t else f"in {at - t:.2f} s"
            reason = (
                f"guard: {robot_body} would come within {d * 1000:.1f} mm of {env_body} {when} "
                f"(limit {cfg.min_distance * 1000:.0f} mm)"
            )
        elif com_margin is not None and com_margin < cfg.min_com_margin:
            reason = (
                f"guard: centre of mass {com_margin * 1000:.1f} mm inside the support polygon "
                f"(limit {cfg.min_com_margin * 1000:.0f} mm)"
            )
        return GuardVerdict(not reason, reason, d, at, robot_body, env_body, com_margin)
