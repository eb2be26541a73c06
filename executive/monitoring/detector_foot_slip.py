"""The foot-slip check: verdict ``slip`` when a foot that stands on the floor slides or turns.

A foot stands while its soles touch the floor and the behaviour declares it a support foot
(``Phase.support``: a step's stance foot on one foot, both feet in its weight shifts; every
foot during any other motion). From the check at which it starts standing, the part of its
sole that touches the floor may slide at most ``foot_slip`` along the floor and the foot may
turn at most ``foot_slip_yaw_deg`` about the vertical while it carries at least
``foot_slip_load`` of the robot's weight; beyond either it has slipped.

Each check follows the middle of the sole (its footprint's middle, at the floor) and the
foot's heading: a few float operations per foot. Only when either is past its limit does it
look at the foot's contacts: their normal force (a foot that carries less is measured afresh
from where it is: it skims the floor, the robot does not stand on it) and how far the sole's
points that touch the floor now have moved since it started standing (a foot that rolls onto
an edge moves its middle, not its edge). A foot that stops standing (lifted, or no longer a
support foot) is measured afresh when it stands again. The limits default to the robot's sole
(docs/detectors.md, "Foot slip").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.monitoring.detector_base import DetectorError, DetectorThresholds, Failure, Phase
from executive.monitoring.detector_contacts import ContactCheck
from executive.world.model import World

__all__ = ["SLIDE_FRACTION", "FootSlip", "FootSlipCheck", "sole_frame"]

#: The default slide limit as a share of the sole's half width (its middle's distance to its
#: nearest edge): the share the step planner keeps the CoM inside the stance sole
#: (``StepConfig.single_support_fraction``): a stance foot that slid further has taken all of that
#: room from under the CoM.
SLIDE_FRACTION = 0.4


@dataclass(frozen=True)
class FootSlip:
    """How far a standing foot moved from where it started standing (the largest seen, or a slip's).

    side: the foot; distance: m its sole slid along the floor (a slip's: its touching points'
    largest slide; the largest seen: its middle's); turn: rad it turned about the vertical;
    speed: m/s its touching points moved along the floor at ``time`` (s); load: the share of the
    robot's weight it carried; since: s at which it started standing.
    """

    side: str = ""
    distance: float = 0.0
    turn: float = 0.0
    speed: float = 0.0
    time: float = 0.0
    load: float = 0.0
    since: float = 0.0


def sole_frame(world: World, side: str) -> tuple[NDArray[np.float64], float, float]:
    """The ``side`` foot's sole in its body's frame, from the world's current state (feet flat).

    Returns:
        The sole's middle at the floor (body frame, m), its half length along the foot's heading
        and its half width across it (m), from the sole geoms' bounding boxes.
    """
    m, d = world.model, world.data
    body = int(m.body(world.profile.feet[side].body).id)
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    corners = np.vstack(
        [
            d.geom_xpos[g]
            + (m.geom_aabb[g, :3] + signs * m.geom_aabb[g, 3:]) @ d.geom_xmat[g].reshape(3, 3).T
            for g in world.ids.foot_geoms[side]
        ]
    )
    rot = d.xmat[body].reshape(3, 3)
    heading = rot[:2, 0] / max(float(np.hypot(*rot[:2, 0])), 1e-9)
    across = np.array([-heading[1], heading[0]])
    along, side_ = corners[:, :2] @ heading, corners[:, :2] @ across
    middle = heading * (along.max() + along.min()) / 2 + across * (side_.max() + side_.min()) / 2
    bottom = np.array([middle[0], middle[1], corners[:, 2].min()])
    local = rot.T @ (bottom - d.xpos[body])
    return local, float(np.ptp(along)) / 2, float(np.ptp(side_)) / 2


class FootSlipCheck:
    """Verdict ``slip`` from the feet's poses while they stand (a few float operations a foot).

    Reads the contact geom pairs the contact check found at its last check
    (``ContactCheck.pairs``: run it first). ``slide`` (m), ``turn_deg`` and ``load`` (a share of
    the robot's weight): the limits in force; :attr:`largest`: the largest slide and turn of a
    standing foot's middle seen so far; :meth:`measure`: a standing foot's slip from its contacts
    now; ``slipped``: the last slip (None before one).

    Raises:
        DetectorError: a limit in ``thresholds`` that is not a positive number.
    """

    def __init__(self, world: World, thresholds: DetectorThresholds, contacts: ContactCheck) -> None:
        m, d, ids = world.model, world.data, world.ids
        self._m, self._d = m, d
        self._contacts = contacts
        self.sides = tuple(world.profile.feet)
        self._bodies = [int(m.body(world.profile.feet[s].body).id) for s in self.sides]
        frames = [sole_frame(world, s) for s in self.sides]
        self._sole = [tuple(float(v) for v in f[0]) for f in frames]  # the sole's middle, body frame
        half_length = min(f[1] for f in frames)
        half_width = min(min(f[1], f[2]) for f in frames)
        th = thresholds
        self.slide = _limit("foot_slip", th.foot_slip, SLIDE_FRACTION * half_width)
        # None: the turn that moves the sole's toe by the slide limit
        self.turn_deg = _limit(
            "foot_slip_yaw_deg", th.foot_slip_yaw_deg, math.degrees(self.slide / half_length)
        )
        self.load = _limit("foot_slip_load", th.foot_slip_load, 0.0)
        self._weight = world.robot_mass * float(np.linalg.norm(m.opt.gravity))
        self._slide_sq = self.slide**2
        self._cos_turn_sq = math.cos(math.radians(self.turn_deg)) ** 2
        # Cached flat views into MjData (its buffers never move): a foot's rotation rows x and y
        # are xmat[9 b : 9 b + 6], its position's x and y xpos[3 b : 3 b + 2].
        self._xmat, self._xpos = memoryview(d.xmat.reshape(-1)), memoryview(d.xpos.reshape(-1))
        # geom -> foot index for the soles (-1 elsewhere); the ground: the floor (or the world's geoms)
        self._foot_of = np.full(m.ngeom, -1, dtype=np.intp)
        for k, s in enumerate(self.sides):
            self._foot_of[list(ids.foot_geoms[s])] = k
        ground = [ids.floor_geom] if ids.floor_geom >= 0 else np.flatnonzero(m.geom_bodyid == 0).tolist()
        self._ground = np.zeros(m.ngeom, dtype=bool)
        self._ground[ground] = True
        self._ground_of, self._foot_list = self._ground.tolist(), self._foot_of.tolist()
        n = len(self.sides)
        self._support = [True] * n
        self._touching = [False] * n
        self._pairs: bytes | None = None  # the contact geom pairs _touching was found for
        # per foot: [standing, x, y, heading x, heading y, since]: where its sole's middle was and
        # where it headed (unit, in the floor's plane) when it started standing, and when
        self._standing: list[list[Any]] = [[False, 0.0, 0.0, 1.0, 0.0, 0.0] for _ in range(n)]
        self._pose = [(np.zeros(3), np.eye(3)) for _ in range(n)]  # its body's pose then
        # the feet to follow: (foot, its _standing, its xmat and xpos offsets, its sole's middle)
        self._watched: list[tuple[Any, ...]] = []
        self._largest: tuple[float, int, float] = (0.0, -1, 0.0)  # slide squared, foot, time
        self._turned: tuple[float, int, float] = (1.0, -1, 0.0)  # the turn's signed cos squared, foot, time
        self.slipped: FootSlip | None = None

    def set_phase(self, phase: Phase) -> None:
        """Watch the phase's support feet (every foot when it names none)."""
        support = phase.support
        self._support = [support is None or s in support for s in self.sides]
        self._watch()

    def _watch(self) -> None:
        """The feet to follow (touching the ground and support feet); the others stop standing."""
        watched = []
        for k, standing in enumerate(self._standing):
            if self._touching[k] and self._support[k]:
                body = self._bodies[k]
                watched.append((k, standing, 9 * body, 3 * body, *self._sole[k]))
            else:
                standing[0] = False
        self._watched = watched

    def check(self, t: float) -> Failure | None:
        """A ``slip`` failure naming the foot, how far, how much it turned and how fast, or None."""
        pairs = self._contacts.pairs
        if pairs != self._pairs:
            self._touching = self._touch(pairs)
            self._pairs = pairs
            self._watch()
        watched = self._watched
        if not watched:
            return None
        xmat, xpos = self._xmat, self._xpos
        found = None
        for k, standing, i, j, o0, o1, o2 in watched:
            r0, r1, r2, r3, r4, r5 = xmat[i : i + 6].tolist()
            p0, p1 = xpos[j : j + 2].tolist()
            x = p0 + r0 * o0 + r1 * o1 + r2 * o2  # the sole's middle, xy
            y = p1 + r3 * o0 + r4 * o1 + r5 * o2
            if not standing[0]:  # starts standing: measured from here
                self._stand(k, x, y, r0, r3, t)
                continue
            dx, dy = x - standing[1], y - standing[2]
            slide_sq = dx * dx + dy * dy
            dot = r0 * standing[3] + r3 * standing[4]  # the heading now (x axis on the floor) on the start's
            dot_sq, size = dot * dot, r0 * r0 + r3 * r3  # the turn's cosine squared: dot_sq / size
            if slide_sq > self._largest[0]:
                self._largest = (slide_sq, k, t)
            if dot_sq < self._turned[0] * size or dot < 0.0:
                self._turned = (math.copysign(dot_sq / size, dot), k, t)
            if slide_sq > self._slide_sq or dot_sq < self._cos_turn_sq * size or dot < 0.0:
                found = found or self._confirm(t, k, x, y, r0, r3)
        return found

    @property
    def largest(self) -> tuple[FootSlip, FootSlip]:
        """The largest slide and the largest turn of a standing foot seen so far (side, distance
        or turn, time; an empty side: no foot stood yet)."""
        (slide_sq, k, t), (cos_sq, j, u) = self._largest, self._turned
        cos = math.copysign(math.sqrt(abs(cos_sq)), cos_sq)
        return (
            FootSlip(self.sides[k] if k >= 0 else "", math.sqrt(slide_sq), time=t),
            FootSlip(self.sides[j] if j >= 0 else "", turn=math.acos(max(-1.0, min(1.0, cos))), time=u),
        )

    def _stand(self, k: int, x: float, y: float, hx: float, hy: float, t: float) -> None:
        """Foot ``k`` starts standing: its sole's middle at ``x``, ``y``, heading ``hx``, ``hy``."""
        size = max(math.hypot(hx, hy), 1e-9)  # the x axis's share in the floor's plane
        self._standing[k][:] = [True, x, y, hx / size, hy / size, t]
        body = self._bodies[k]
        self._pose[k] = (self._d.xpos[body].copy(), self._d.xmat[body].reshape(3, 3).copy())

    def _touch(self, pairs: bytes) -> list[bool]:
        """Which feet's soles touch the ground among the contacts' geom pairs (``pairs``: their bytes)."""
        touching = [False] * len(self.sides)
        ground, foot_of = self._ground_of, self._foot_list
        flat = np.frombuffer(pairs, dtype=np.int32).tolist()
        for a, b in zip(flat[::2], flat[1::2], strict=True):  # a few contacts: plain Python is quicker
            k = foot_of[a] if ground[b] else foot_of[b] if ground[a] else -1
            if k >= 0:
                touching[k] = True
        return touching

    def _feet_of(self, geom: NDArray[np.int32]) -> NDArray[np.intp]:
        """The foot each contact (geom pair) puts on the ground, -1 for the others."""
        a, b = geom[:, 0], geom[:, 1]
        return np.where(self._ground[b], self._foot_of[a], np.where(self._ground[a], self._foot_of[b], -1))

    def measure(self, side: str, t: float) -> FootSlip | None:
        """The ``side`` foot's slip so far, from its contacts now: how far its points on the floor
        slid and how much it turned since it started standing, how fast they slide and the share
        of the weight it carries, at time ``t``; None while it does not stand."""
        k = self.sides.index(side)
        ok, _, _, h0x, h0y, since = self._standing[k]
        if not ok:
            return None
        m, d = self._m, self._d
        contacts = np.flatnonzero(self._feet_of(d.contact.geom) == k)
        force, wrench = 0.0, np.zeros(6)
        for i in contacts.tolist():
            mujoco.mj_contactForce(m, d, i, wrench)
            force += float(wrench[0])
        body = self._bodies[k]
        now, rot = d.xpos[body], d.xmat[body].reshape(3, 3)
        hx, hy = float(rot[0, 0]), float(rot[1, 0])
        turn = abs(math.atan2(h0x * hy - h0y * hx, h0x * hx + h0y * hy))
        if not len(contacts):
            return FootSlip(side, 0.0, turn, 0.0, t, 0.0, since)
        points = d.contact.pos[contacts]  # where the sole touches the floor now (world)
        then, rot0 = self._pose[k]
        before = then + ((points - now) @ rot) @ rot0.T  # the same points of the sole, when it stood
        distance = float(np.max(np.hypot(*(points - before)[:, :2].T)))
        velocity = np.zeros(6)  # (angular, linear) at the body's origin, world frame
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, body, velocity, 0)
        arm = points.mean(axis=0) - now
        speed = float(np.hypot(*(velocity[3:5] + np.cross(velocity[:3], arm)[:2])))
        return FootSlip(side, distance, turn, speed, t, force / self._weight, since)

    def _confirm(self, t: float, k: int, x: float, y: float, hx: float, hy: float) -> Failure | None:
        """Foot ``k``'s middle slid or turned past a limit (it is at ``x``, ``y``, heading ``hx``,
        ``hy``): a slip when its points on the floor did too while it carries ``load``; a foot
        that carries less is measured afresh from here."""
        slip = self.measure(self.sides[k], t)
        assert slip is not None  # foot k stands
        if slip.load < self.load:
            self._stand(k, x, y, hx, hy, t)
            return None
        if slip.distance <= self.slide and slip.turn <= math.radians(self.turn_deg):
            return None  # rolled onto an edge, or turned within its limit: no slip
        self.slipped = slip
        self._standing[k][0] = False  # measured afresh from where it stands now
        name = str(self._m.body(self._bodies[k]).name)
        detail = (
            f"slip: the {slip.side} foot ({name}) slid {slip.distance * 1000:.0f} mm along the floor (limit "
            f"{self.slide * 1000:.0f} mm) and turned {math.degrees(slip.turn):.1f} deg (limit "
            f"{self.turn_deg:.1f} deg) since it stood at t={slip.since:.3f} s, sliding at "
            f"{slip.speed * 1000:.0f} mm/s under {slip.load * 100:.0f} % of the weight, at t={t:.3f} s"
        )
        return Failure("slip", detail, t, (name,))


def _limit(name: str, value: float | None, default: float) -> float:
    """``value`` if given (a positive number), else ``default``."""
    if value is None:
        return default
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
        raise DetectorError(f"DetectorThresholds.{name}: {value!r} is not a positive number of its unit")
    return float(value)
