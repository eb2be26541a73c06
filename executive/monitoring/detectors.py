"""Failure detectors: decide, from the TRUTH world's physics, what happened during a behaviour.

The detectors are independent of the planner and of the risk models: they look only at
the MuJoCo state after each ``mj_step`` and at the phase the executing behaviour
declares (which hand carries or is closing on which object, which object is being put
down). The first failure is latched; later calls return it again.

Failure modes
-------------
``unstable``
    A NaN or inf in ``qpos``, ``qvel`` or ``qacc``; any ``|qvel|`` above
    ``max_qvel``; or any MuJoCo warning counter (``data.warning[i].number``) higher
    than when the detector was made (the detail names the ``mjtWarning``). Checked
    first: with a broken state the other checks mean nothing. MuJoCo itself resets
    the data after a bad qpos/qvel/qacc (its auto-reset), so the warning counter is
    what still shows it afterwards.
``fall``
    The robot left its safe posture (``profile.safe_posture``, :mod:`executive.robot.posture`, the
    one the planner keeps every plan inside) by more than the posture's tolerance: the base
    (pelvis) more than ``max_pelvis_drop + pelvis_tolerance`` below its standing height
    (the keyframe's), or the torso's z axis more than ``max_trunk_tilt_deg +
    tilt_tolerance_deg`` from vertical (``DetectorThresholds.pelvis_drop`` and
    ``trunk_tilt_deg`` override either); or a robot geom other than the soles touching the
    floor (contact normal force at least ``collision_force``). A planned squat within the
    posture is not a fall; a pelvis that sinks below the deepest plan by more than the
    tolerance is.
``drop``
    A carried object farther than ``hold_distance`` from the holding hand's site
    (the distance from the site to the object's surface: 0 while the site is inside
    the object, as between closed jaws); any object touching the floor; or a failed
    :meth:`FailureDetector.check_placed`.
    A hand that lands on the object it is approaching to grasp (``set_phase(approaching=...)``)
    with at least ``collision_force`` is a drop too: its jaws missed the object (a grasp
    misaligned beyond the jaws' clearance), the failure the grasp risk predicts; it is not
    counted as a collision, whose risk model allows a hand to touch what it grasps.
``collision``
    Any contact that is not allowed (below) with normal force at least
    ``collision_force`` (``mujoco.mj_contactForce``): the robot touching the table,
    an obstacle, or an object it is not grasping or carrying; a carried object
    touching the table (unless it is being placed), an obstacle or another object;
    any object touching an obstacle.

Allowed contacts
----------------
- the robot's sole geoms with the floor;
- every object with the table (top or legs) while it is not carried (resting), and
  the object being placed (``set_phase(placing=...)``) even while still carried
  (``set_phase`` declares the phase; each call replaces the previous one);
- objects with each other while neither is carried (a stack);
- an object with the hand geoms (the subtree of that side's hand body) of a side
  that is grasping (closing on), carrying or pushing it (a pushed object slides on the
  table away from the hand as it likes: no hold distance; it touching another object
  is a collision);
- an obstacle with the hand geoms of a side that presses it (``set_phase(grasping=(side,
  obstacle))``, a press task's hold); any other contact of that hand is still a collision;
- the robot's own self-contacts: never a failure (the embedded humanoid excludes
  adjacent links explicitly, so one is rare), but counted, with the largest force,
  in :attr:`FailureDetector.closest_call`.

Forces and order
----------------
A contact's force is the total normal force (``mujoco.mj_contactForce``) of all the
contact points MuJoCo made for that geom pair in the step; forbidden pairs below
``collision_force`` are grazes: not failures, but the largest is kept in the closest
call. When several things go wrong in one step, the first in this order is reported:
unstable, fall (height, tilt), drop (hold distance), then the contacts, the worst
kind first (floor under the robot > object on the floor > collision), the strongest
of a kind first.

Closest call
------------
Besides grazes and self-contacts, :attr:`FailureDetector.closest_call` holds the
smallest clearance of a forbidden pair (the robot or an object vs. the table, the
obstacles and the objects it may not touch now; the floor is left out), computed
every ``distance_stride`` checks: a vectorised lower bound (a mover's bounding
sphere vs. the static boxes in their own frames, bounding spheres for moving
things) selects the pairs that could beat the best so far within
``clearance_horizon``, and ``mujoco.mj_geomDistance`` gives their exact distance.

Cost
----
``check()`` reads cached views into ``MjData``; the state checks are a few dot
products and float operations; the contacts are classified by a lookup in a geom x
geom code table built by ``set_phase`` (contact forces are computed only for contacts
that are not plainly allowed), and a step whose contact geom pairs are those of the
last check, all allowed then, is not classified again (``set_phase`` forgets that).
Measured on the book world: 8 to 15 us per check (machine load) against 45 to 55 us
per ``mj_step`` (tests/test_detectors.py prints both). :meth:`FailureDetector.check_contacts`
is the contact part alone (1 to 2 us while the contacts are unchanged): the simulated robot
calls it after every physics step inside a control period and the full check after the
period's last step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.errors import ExecutiveError
from executive.robot.posture import standing_pelvis_height
from executive.world.model import World

__all__ = [
    "ClosestCall",
    "DetectorError",
    "DetectorThresholds",
    "Failure",
    "FailureDetector",
]

# Contact codes of the geom x geom table; 0 means allowed and silent.
_ALLOWED = 0
_SELF = 1
_COLLISION = 2
_FALL = 3  # a non-sole robot geom on the floor
_DROP = 4  # an object on the floor
_MISGRASP = 5  # a hand on the object it approaches to grasp: the jaws missed it
_SEVERITY = {_COLLISION: 1, _MISGRASP: 1, _DROP: 2, _FALL: 3}  # several in one step: report the worst
_BOX, _SPHERE, _CYLINDER = (
    int(mujoco.mjtGeom.mjGEOM_BOX),
    int(mujoco.mjtGeom.mjGEOM_SPHERE),
    int(mujoco.mjtGeom.mjGEOM_CYLINDER),
)


class DetectorError(ExecutiveError, ValueError):
    """A detector was asked about a side or an object the world does not have."""


@dataclass(frozen=True)
class Failure:
    """What went wrong, when, and (for contacts) between which bodies and how hard."""

    mode: str  # a verdict of the failure-mode table (executive.schema.failure_modes)
    detail: str  # human-readable: names bodies/geoms, force in N, heights/angles, times
    time: float  # simulation time (s)
    bodies: tuple[str, ...] = ()  # body names involved (collision)
    force: float = 0.0  # contact normal force magnitude in N (collision)


@dataclass(frozen=True)
class DetectorThresholds:
    """When an observation counts as a failure; every default with its reason."""

    # m below the standing height => fall. None: the robot's safe posture's limit plus its
    # tolerance (SafePosture.fall_pelvis_drop): the planner plans no deeper than the limit.
    pelvis_drop: float | None = None
    # deg of the torso's z axis from vertical => fall. None: the safe posture's
    # (SafePosture.fall_tilt_deg).
    trunk_tilt_deg: float | None = None
    # N; contacts below this are grazes, ignored (kept as the closest call). 1 N is about
    # the weight of 0.1 kg: any deliberate push exceeds it, solver noise of a touch does not.
    collision_force: float = 1.0
    # m from the holding hand's site to the carried object's surface => drop. The site is
    # between the pads, inside a held object; 5 cm out means it left the jaws.
    hold_distance: float = 0.05
    # m in the table plane between the placed object's centre and its target: the
    # placement accuracy a later grasp of the object tolerates.
    place_position_tol: float = 0.02
    # deg of yaw error of a placed object (checked only when the task gives a yaw).
    place_yaw_tol_deg: float = 10.0
    # rad/s or m/s; beyond => unstable. Servoed joints move at a few rad/s, a falling
    # body at a few m/s; 100 is only reached by a diverging simulation.
    max_qvel: float = 100.0
    # m/s below which a placed object counts as resting (and 10x this in rad/s): 2 cm/s
    # is slower than any deliberate motion, faster than solver creep of a resting box.
    rest_speed: float = 0.02
    # deg of a placed object's z axis from vertical beyond which it has tipped over.
    place_tilt_deg: float = 10.0
    # m; clearances larger than this are not computed (broad phase of the closest call).
    clearance_horizon: float = 0.20


@dataclass(frozen=True)
class ClosestCall:
    """The nearest thing to a failure seen so far, for the report.

    ``distance``: the smallest clearance (m) between a forbidden pair, ``inf`` when no
    pair came within ``clearance_horizon``; negative when it penetrated (then the
    contact force tells whether it was a graze). ``ignored_force``: the largest normal
    force (N) of a forbidden contact below ``collision_force``. ``self_contacts``: how
    many robot self-contacts (summed over steps) were seen; ``self_force``: the largest.
    """

    distance: float = math.inf
    distance_bodies: tuple[str, ...] = ()
    distance_time: float = 0.0
    ignored_force: float = 0.0
    ignored_bodies: tuple[str, ...] = ()
    ignored_time: float = 0.0
    self_contacts: int = 0
    self_force: float = 0.0
    self_bodies: tuple[str, ...] = ()

    def describe(self) -> str:
        """One line for the report."""
        parts = []
        if math.isfinite(self.distance):
            a, b = self.distance_bodies
            parts.append(f"closest {a}-{b} {self.distance * 1000:.1f} mm at t={self.distance_time:.2f} s")
        else:
            parts.append("nothing came within the clearance horizon")
        if self.ignored_bodies:
            a, b = self.ignored_bodies
            parts.append(f"largest graze {a}-{b} {self.ignored_force:.2f} N at t={self.ignored_time:.2f} s")
        if self.self_contacts:
            largest = f"{'-'.join(self.self_bodies)} " if self.self_bodies else ""
            parts.append(f"{self.self_contacts} self-contacts (largest {largest}{self.self_force:.1f} N)")
        return "; ".join(parts)


class FailureDetector:
    """Watches one execution in a truth world; call :meth:`check` after every ``mj_step``.

    Make one detector per execution, with the world in its start state: the MuJoCo warning
    counters are taken at construction (and the start pelvis height, ``start_height``, for
    the report); the fall limits are the robot's safe posture's unless ``thresholds`` sets them.
    ``distance_stride``: compute the closest clearance every this many checks (0: never).
    """

    def __init__(
        self, world: World, thresholds: DetectorThresholds | None = None, *, distance_stride: int = 10
    ) -> None:
        self.world = world
        self.thresholds = thresholds or DetectorThresholds()
        m, d = world.model, world.data
        self._m, self._d = m, d
        ids = world.ids
        th = self.thresholds
        # Cached views into MjData (its buffers never move).
        self._qpos, self._qvel, self._qacc = d.qpos, d.qvel, d.qacc
        self._xpos, self._xmat, self._site_xpos = d.xpos, d.xmat, d.site_xpos
        self._geom_xpos, self._geom_xmat = d.geom_xpos, d.geom_xmat
        self._geom_type: list[int] = m.geom_type.tolist()
        self._warnings = d.warning.number
        self._warnings0 = np.array(self._warnings, dtype=np.int64)
        self._warnings0_bytes = self._warnings.tobytes()
        self._max_qvel_sq = self.thresholds.max_qvel**2
        self._base, self._torso = ids.base_body, ids.torso_body
        self.start_height = float(d.xpos[ids.base_body][2])
        posture = world.profile.safe_posture
        #: m: the pelvis height of the standing keyframe, which the pelvis limit is measured from.
        self.standing_height = standing_pelvis_height(m, ids.keyframe, ids.base_body)
        #: m below standing and deg from vertical beyond which the robot has fallen.
        self.pelvis_drop = th.pelvis_drop if th.pelvis_drop is not None else posture.fall_pelvis_drop
        self.trunk_tilt_deg = th.trunk_tilt_deg if th.trunk_tilt_deg is not None else posture.fall_tilt_deg
        self._min_height = self.standing_height - self.pelvis_drop
        self._min_cos_tilt = math.cos(math.radians(self.trunk_tilt_deg))
        self._force = np.zeros(6)
        self._stride = max(0, int(distance_stride))
        self._n_checks = 0
        self._clearance_at = 0  # _n_checks at the last clearance
        self._last_time = float(d.time)
        self._failure: Failure | None = None
        self._closest = ClosestCall()

        # Id sets.
        robot = np.array(ids.robot_geoms, dtype=np.int64)
        soles = np.array([g for gs in ids.foot_geoms.values() for g in gs], dtype=np.int64)
        self._hand_geoms: dict[str, NDArray[np.int64]] = {
            side: np.array([g for g in ids.robot_geoms if m.geom_bodyid[g] in set(bodies)], dtype=np.int64)
            for side, bodies in ids.hand_bodies.items()
        }
        self._object_geom = dict(ids.object_geoms)
        self._obstacle_geom = dict(ids.obstacle_geoms)
        self._robot_set = frozenset(ids.robot_geoms)
        self._object_set = frozenset(ids.object_geoms.values())
        self._table = np.array(ids.table_geoms, dtype=np.int64)
        self._table_top = ids.table_geoms[0] if ids.table_geoms else -1
        objects = np.array(list(ids.object_geoms.values()), dtype=np.int64)
        obstacles = np.array(list(ids.obstacle_geoms.values()), dtype=np.int64)
        floor = np.array([ids.floor_geom] if ids.floor_geom >= 0 else [], dtype=np.int64)

        base = self._base_codes = self._code_table(robot, soles, objects, obstacles, floor)
        self._clearance_setup(
            np.concatenate([robot, objects]), np.concatenate([self._table, obstacles, objects])
        )
        self._codes = base.copy()
        self._code_rows: list[list[int]] = base.tolist()
        self._carried: tuple[str, str] | None = None
        self._grasping: tuple[str, str] | None = None
        self._placing: str | None = None
        self._approaching: tuple[str, str] | None = None
        self._pushing: tuple[str, str] | None = None
        self.set_phase()

    @staticmethod
    def _put(a: NDArray[np.int64], b: NDArray[np.int64], code: int, table: NDArray[np.int8]) -> None:
        """Set ``code`` for every geom pair of ``a`` x ``b`` (both ways) in ``table``."""
        table[np.ix_(a, b)] = code
        table[np.ix_(b, a)] = code

    def _code_table(
        self,
        robot: NDArray[np.int64],
        soles: NDArray[np.int64],
        objects: NDArray[np.int64],
        obstacles: NDArray[np.int64],
        floor: NDArray[np.int64],
    ) -> NDArray[np.int8]:
        """The geom x geom contact codes with no phase declared (module doc, "Allowed contacts")."""
        m, put = self._m, self._put
        base = np.zeros((m.ngeom, m.ngeom), dtype=np.int8)
        put(robot, robot, _SELF, base)
        put(robot, floor, _FALL, base)
        put(soles, floor, _ALLOWED, base)
        for env in (self._table, obstacles, objects):
            put(robot, env, _COLLISION, base)
        put(objects, floor, _DROP, base)
        put(objects, obstacles, _COLLISION, base)
        put(objects, self._table, _ALLOWED, base)
        put(objects, objects, _ALLOWED, base)
        return base

    def _clearance_setup(self, movers: NDArray[np.int64], candidates: NDArray[np.int64]) -> None:
        """The closest call's broad phase: moving geoms (robot, objects) vs scene things.

        Things welded to the world (table, obstacles) are boxes whose frames never move: a mover's
        centre is taken into all of them with one matrix product. Things that move (objects, any
        obstacle that is not static) use their bounding spheres.
        """
        m, d = self._m, self._d
        self._clr_movers = movers
        is_box = m.geom_type[candidates] == mujoco.mjtGeom.mjGEOM_BOX
        welded = m.body_weldid[m.geom_bodyid[candidates]] == 0
        static = candidates[is_box & welded]
        moving = candidates[~(is_box & welded)]
        self._clr_things = np.concatenate([static, moving])
        self._clr_moving = moving
        n_static, n_moving = len(static), len(moving)
        rot = d.geom_xmat[static].reshape(-1, 3, 3)
        eye = np.broadcast_to(np.eye(3), (n_moving, 3, 3))
        self._clr_frames = np.concatenate([rot, eye]).transpose(1, 0, 2).reshape(3, -1)
        self._clr_origins = np.concatenate(
            [np.einsum("ki,kij->kj", d.geom_xpos[static], rot).reshape(-1), np.zeros(3 * n_moving)]
        )
        self._clr_half = np.concatenate([m.geom_size[static].reshape(-1), np.zeros(3 * n_moving)])
        # Sums the three squared components of each thing's block: (3 K) x K.
        self._clr_sum = np.kron(np.eye(n_static + n_moving), np.ones((3, 1)))
        rb_movers = m.geom_rbound[movers][:, None]
        self._clr_base_offset = np.concatenate(
            [np.broadcast_to(-rb_movers, (len(rb_movers), n_static)), -rb_movers - m.geom_rbound[moving]],
            axis=1,
        )
        self._n_static = n_static
        self._clr_offset = self._clr_base_offset
        self._clr_best = math.nan
        self._clr_limit_sq = np.zeros_like(self._clr_base_offset)

    # --- phase ---------------------------------------------------------------------------

    def set_phase(
        self,
        *,
        carried: tuple[str, str] | None = None,
        grasping: tuple[str, str] | None = None,
        placing: str | None = None,
        approaching: tuple[str, str] | None = None,
        pushing: tuple[str, str] | None = None,
    ) -> None:
        """Declare what the behaviour does now; each call replaces the previous phase.

        carried: (side, object) the hand holds now; grasping: (side, object) the hand may
        touch now (closing on it), or (side, obstacle) it presses; placing: the object allowed
        to touch the table now;
        approaching: (side, object) the open hand is moving onto to grasp: a forceful touch
        now is a misaligned grasp (mode ``drop``), not a collision; pushing: (side, object) the
        hand slides along the table: that hand may touch it, it may touch the table and slide
        away from the hand (no hold distance), and it touching another object is a collision.
        A handover carries with one side and grasps with the other.
        """
        codes = self._base_codes.copy()
        put = self._put
        for pair in (carried, grasping, approaching, pushing):
            if pair is not None:
                self._check_side(pair[0])
                if pair is not grasping or pair[1] not in self._obstacle_geom:  # a press touches an obstacle
                    self._check_object(pair[1])
        if placing is not None:
            self._check_object(placing)
        if carried is not None:
            side, name = carried
            g = np.array([self._object_geom[name]], dtype=np.int64)
            others = np.array([v for k, v in self._object_geom.items() if k != name], dtype=np.int64)
            put(g, self._table, _COLLISION, codes)
            put(g, others, _COLLISION, codes)
            put(g, self._hand_geoms[side], _ALLOWED, codes)
        if approaching is not None:
            side, name = approaching
            g = np.array([self._object_geom[name]], dtype=np.int64)
            put(g, self._hand_geoms[side], _MISGRASP, codes)
        if grasping is not None:
            side, name = grasping
            g = np.array([self._object_geom.get(name, self._obstacle_geom.get(name))], dtype=np.int64)
            put(g, self._hand_geoms[side], _ALLOWED, codes)
        if placing is not None:
            g = np.array([self._object_geom[placing]], dtype=np.int64)
            put(g, self._table, _ALLOWED, codes)
        if pushing is not None:
            side, name = pushing
            g = np.array([self._object_geom[name]], dtype=np.int64)
            others = np.array([v for k, v in self._object_geom.items() if k != name], dtype=np.int64)
            put(g, others, _COLLISION, codes)
            put(g, self._hand_geoms[side], _ALLOWED, codes)
        self._codes = codes
        self._code_rows = codes.tolist()
        self._quiet_pairs = b""  # the codes changed: classify the next contacts afresh
        self._carried, self._grasping, self._placing = carried, grasping, placing
        self._approaching, self._pushing = approaching, pushing
        # Forbidden pairs for the clearance (floor excluded: its distance says nothing); +inf
        # on the pairs that may touch, so they never beat the best clearance.
        forbidden = codes[np.ix_(self._clr_movers, self._clr_things)] == _COLLISION  # not _MISGRASP
        forbidden &= self._clr_movers[:, None] != self._clr_things[None, :]
        self._clr_offset = np.where(forbidden, self._clr_base_offset, np.inf)
        self._clr_best = math.nan  # recompute the squared thresholds at the next clearance

    @property
    def phase(self) -> dict[str, object]:
        """The phase last set (for logging)."""
        return {
            "carried": self._carried,
            "grasping": self._grasping,
            "placing": self._placing,
            "approaching": self._approaching,
            "pushing": self._pushing,
        }

    # --- results -------------------------------------------------------------------------

    @property
    def failure(self) -> Failure | None:
        """The first failure seen, or None."""
        return self._failure

    @property
    def closest_call(self) -> ClosestCall:
        """The smallest clearance, largest ignored contact and self-contacts seen so far."""
        return self._closest

    # --- the per-step check --------------------------------------------------------------

    def acknowledge(self) -> Failure | None:
        """Clear the latched failure (it has been reported) so a new attempt is watched afresh."""
        failure, self._failure = self._failure, None
        return failure

    def check(self) -> Failure | None:
        """Look at the current state (call after each ``mj_step``, or at least after the last
        step of each control period with :meth:`check_contacts` after the others); the first
        failure is latched."""
        if self._failure is not None:
            return self._failure
        d = self._d
        t = float(d.time)
        found = self._unstable(t) or self._fall(t) or self._held(t) or self._contacts(t)
        self._n_checks += 1
        if found is None and self._stride and self._n_checks - self._clearance_at >= self._stride:
            self._clearance_at = self._n_checks
            self._clearance(t)
        self._last_time = t
        if found is not None:
            self._failure = found
        return found

    def check_contacts(self) -> Failure | None:
        """The contact part of :meth:`check` alone, for the physics steps inside a control period.

        Contacts are what one physics step can make and take away again (a graze, a hit that
        bounces off), so they are looked at after every step. The state checks can wait for the
        end of the period (:meth:`check`, at most ``control_dt`` later): a NaN or a warning
        stays in the state or in MuJoCo's warning counters, and a fall (``pelvis_drop``, a
        ``trunk_tilt_deg`` lean) or a drop (``hold_distance`` from the jaws) takes far longer
        than a control period (free fall covers 2 mm in 20 ms). Counts as a check for the
        clearance stride (every ``distance_stride`` steps).
        """
        if self._failure is not None:
            return self._failure
        d = self._d
        t = float(d.time)
        if t < self._last_time:  # MuJoCo's auto-reset after a bad state: the full check sees it
            return self.check()
        self._n_checks += 1
        self._last_time = t
        if not d.ncon or d.contact.geom.tobytes() == self._quiet_pairs:  # _contacts' fast path
            return None
        found = self._contacts(t)
        if found is not None:
            self._failure = found
        return found

    def _unstable(self, t: float) -> Failure | None:
        if self._warnings.tobytes() != self._warnings0_bytes:  # fast path: unchanged counters
            found = self._warning_failure(t)
            if found is not None:
                return found
        # Fast path: NaN and inf propagate into the dot products, and max|v| <= |v|.
        vv = float(self._qvel @ self._qvel)
        if (
            vv <= self._max_qvel_sq
            and math.isfinite(float(self._qpos @ self._qpos))
            and math.isfinite(float(self._qacc @ self._qacc))
        ):
            return None
        for label, arr in (("qpos", self._qpos), ("qvel", self._qvel), ("qacc", self._qacc)):
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                k = int(bad[0])
                return Failure(
                    "unstable",
                    f"unstable: {label}[{k}] ({self._dof_name(label, k)}) is {arr[k]} at t={t:.3f} s",
                    t,
                )
        k = int(np.argmax(np.abs(self._qvel)))
        if abs(float(self._qvel[k])) <= self.thresholds.max_qvel:
            return None  # a large but finite qpos/qacc sum of squares, or several fast dofs
        return Failure(
            "unstable",
            f"unstable: |qvel[{k}]| ({self._dof_name('qvel', k)}) = {abs(self._qvel[k]):.3g} exceeds "
            f"{self.thresholds.max_qvel:g} at t={t:.3f} s",
            t,
        )

    def _warning_failure(self, t: float) -> Failure | None:
        now = np.array(self._warnings, dtype=np.int64)
        # mj_resetData clears the counters: count from the lower value from then on.
        self._warnings0 = np.minimum(self._warnings0, now)
        self._warnings0_bytes = self._warnings0.astype(self._warnings.dtype).tobytes()
        raised = now - self._warnings0
        if not raised.any():
            return None
        k = int(np.argmax(raised))
        name = mujoco.mjtWarning(k).name
        info = int(self._d.warning[k].lastinfo)
        # MuJoCo's auto-reset after a bad state sets time to 0: report the last time seen.
        when = max(t, self._last_time)
        return Failure(
            "unstable",
            f"unstable: MuJoCo warning {name} raised {int(raised[k])} time(s) since the detector "
            f"started (last info {info}) at t={when:.3f} s",
            when,
        )

    def _fall(self, t: float) -> Failure | None:
        z = float(self._xpos[self._base, 2])
        cos_tilt = float(self._xmat[self._torso, 8])
        if z >= self._min_height and cos_tilt >= self._min_cos_tilt:
            return None
        m = self._m
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, cos_tilt))))
        base, torso = str(m.body(self._base).name), str(m.body(self._torso).name)
        state = (
            f"{base} at {z:.3f} m ({self.standing_height - z:.3f} m below standing "
            f"{self.standing_height:.3f} m, limit {self.pelvis_drop:.3f} m), {torso} tilted {tilt:.1f} deg "
            f"from vertical (limit {self.trunk_tilt_deg:.1f} deg)"
        )
        if z < self._min_height:
            return Failure("fall", f"fall: {base} dropped: {state} at t={t:.3f} s", t, (base,))
        return Failure("fall", f"fall: {torso} tilted: {state} at t={t:.3f} s", t, (torso,))

    def _held(self, t: float) -> Failure | None:
        if self._carried is None:
            return None
        side, name = self._carried
        site = self.world.ids.hand_sites[side]
        dist = self._surface_distance(self._object_geom[name], self._site_xpos[site])
        if dist <= self.thresholds.hold_distance:
            return None
        return Failure(
            "drop",
            f"drop: {name} is {dist:.3f} m from the {side} hand site {self._m.site(site).name} "
            f"(limit {self.thresholds.hold_distance:.3f} m) at t={t:.3f} s",
            t,
            (name, self._m.body(self._m.site_bodyid[site]).name),
        )

    def _contacts(self, t: float) -> Failure | None:
        d = self._d
        if not d.ncon:
            return None
        geom = d.contact.geom
        # The same geom pairs as at the last check, which were all allowed and silent (the
        # common case: feet on the floor, a hand on what it holds): nothing to classify.
        pairs = geom.tobytes()
        if pairs == self._quiet_pairs:
            return None
        codes = self._code_rows
        flagged = [(i, a, b, c) for i, (a, b) in enumerate(geom.tolist()) if (c := codes[a][b])]
        if not flagged:
            self._quiet_pairs = pairs
            return None
        # Total normal force per geom pair: MuJoCo splits one touch into several points.
        totals: dict[tuple[int, int], float] = {}
        pair_code: dict[tuple[int, int], int] = {}
        self_count = 0
        for i, a, b, code in flagged:
            mujoco.mj_contactForce(self._m, d, i, self._force)
            key = (a, b) if a < b else (b, a)
            totals[key] = totals.get(key, 0.0) + abs(float(self._force[0]))
            pair_code[key] = code
            self_count += code == _SELF
        th = self.thresholds.collision_force
        worst: tuple[int, float, tuple[int, int]] | None = None
        c = self._closest
        if self_count:
            c = replace(c, self_contacts=c.self_contacts + self_count)
        for key, f in totals.items():
            code = pair_code[key]
            if code == _SELF:
                if f > c.self_force or not c.self_bodies:  # a zero-force touch names its bodies too
                    c = replace(c, self_force=f, self_bodies=self._pair_labels(key))
            elif f >= th:
                if worst is None or (_SEVERITY[code], f) > worst[:2]:
                    worst = (_SEVERITY[code], f, key)
            elif f > c.ignored_force:
                c = replace(c, ignored_force=f, ignored_bodies=self._pair_labels(key), ignored_time=t)
        self._closest = c
        if worst is None:
            return None
        severity, f, key = worst
        a, b = self._pair_labels(key)
        if pair_code[key] == _MISGRASP:
            return Failure(
                "drop",
                f"drop: {a} landed on {b} with {f:.1f} N at t={t:.3f} s while approaching to grasp it "
                "(the jaws missed it: a misaligned grasp)",
                t,
                (a, b),
                f,
            )
        if severity == _SEVERITY[_FALL]:
            return Failure("fall", f"fall: {a} touched the {b} with {f:.1f} N at t={t:.3f} s", t, (a, b), f)
        if severity == _SEVERITY[_DROP]:
            return Failure("drop", f"drop: {a} touched the {b} with {f:.1f} N at t={t:.3f} s", t, (a, b), f)
        return Failure("collision", f"collision: {a} touched {b} with {f:.1f} N at t={t:.3f} s", t, (a, b), f)

    def _clearance(self, t: float) -> None:
        """Smallest clearance of a forbidden pair, if below the best so far (vectorised broad phase).

        Lower bound per pair: distance from the moving geom's bounding sphere to the other
        geom's oriented box (its bounding sphere when it is not a box); exact distances
        (``mj_geomDistance``) only for pairs whose bound beats the best clearance so far.
        """
        best = min(self._closest.distance, self.thresholds.clearance_horizon)
        if best != self._clr_best:  # squared thresholds follow the best clearance so far
            self._clr_best = best
            self._clr_limit_sq = np.square(np.maximum(best - self._clr_offset, 0.0))
        # Every mover's centre in every thing's frame with one product; moving things (objects)
        # have an identity frame at their current centre and a zero half size (a sphere).
        self._clr_origins[self._n_static * 3 :] = self._geom_xpos[self._clr_moving].reshape(-1)
        local = self._geom_xpos[self._clr_movers] @ self._clr_frames
        local -= self._clr_origins
        np.abs(local, out=local)
        local -= self._clr_half
        np.maximum(local, 0.0, out=local)
        local *= local
        rows, cols = np.nonzero(local @ self._clr_sum < self._clr_limit_sq)
        if not rows.size:
            return
        movers_ids, things = self._clr_movers, self._clr_things
        best_pair: tuple[int, int] | None = None
        for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
            g1, g2 = int(movers_ids[r]), int(things[c])
            dist = float(mujoco.mj_geomDistance(self._m, self._d, g1, g2, best, None))
            if dist < best:
                best, best_pair = dist, (g1, g2)
        if best_pair is not None:
            self._closest = replace(
                self._closest,
                distance=best,
                distance_bodies=self._pair_labels(best_pair),
                distance_time=t,
            )

    # --- the end-of-task check -----------------------------------------------------------

    def check_placed(
        self,
        obj: str,
        target_xy: tuple[float, float],
        target_yaw: float | None = None,
        yaw_symmetry: int = 1,
    ) -> Failure | None:
        """At the end: is ``obj`` resting on the table at ``target_xy`` (and ``target_yaw``, rad)?

        The yaw error counts modulo ``2*pi / yaw_symmetry`` (the object's rotational symmetry
        about the vertical, ``Body.yaw_symmetry``).

        None when it is within ``place_position_tol`` (and ``place_yaw_tol_deg``), upright
        within ``place_tilt_deg``, slower than ``rest_speed`` and touching the table;
        otherwise a ``drop`` failure naming what is off. A failure is also latched when
        none was before.
        """
        self._check_object(obj)
        m, d, th = self._m, self._d, self.thresholds
        t = float(d.time)
        body = self.world.ids.object_bodies[obj]
        pos = d.xpos[body]
        rot = d.xmat[body].reshape(3, 3)
        problems: list[str] = []
        err = math.hypot(float(pos[0]) - target_xy[0], float(pos[1]) - target_xy[1])
        if not err <= th.place_position_tol:
            problems.append(
                f"rests {err:.3f} m from its target ({target_xy[0]:.3f}, {target_xy[1]:.3f}) "
                f"(tolerance {th.place_position_tol:.3f} m) at ({pos[0]:.3f}, {pos[1]:.3f})"
            )
        if target_yaw is not None:
            yaw = math.atan2(float(rot[1, 0]), float(rot[0, 0]))
            dyaw = math.degrees(abs(math.remainder(yaw - target_yaw, 2 * math.pi / max(1, yaw_symmetry))))
            if not dyaw <= th.place_yaw_tol_deg:
                problems.append(f"yaw off by {dyaw:.1f} deg (tolerance {th.place_yaw_tol_deg:.1f} deg)")
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(rot[2, 2])))))
        if not tilt <= th.place_tilt_deg:
            problems.append(f"tipped {tilt:.1f} deg (limit {th.place_tilt_deg:.1f} deg)")
        vel = np.zeros(6)
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, body, vel, 0)
        lin, ang = float(np.linalg.norm(vel[3:])), float(np.linalg.norm(vel[:3]))
        if not (lin <= th.rest_speed and ang <= 10.0 * th.rest_speed):
            problems.append(f"still moving ({lin:.3f} m/s, {ang:.3f} rad/s)")
        g = self._object_geom[obj]
        on_table = any(
            g in pair and self._table_top in pair for pair in (d.contact.geom.tolist() if d.ncon else [])
        )
        if not on_table:
            problems.append(f"not on the table (centre at z={pos[2]:.3f} m)")
        if not problems:
            return None
        failure = Failure("drop", f"drop: {obj} " + "; ".join(problems) + f" at t={t:.3f} s", t, (obj,))
        if self._failure is None:
            self._failure = failure
        return failure

    # --- helpers -------------------------------------------------------------------------

    def _check_side(self, side: str) -> None:
        if side not in self._hand_geoms:
            raise DetectorError(
                f"no hand side '{side}'; the robot has: {', '.join(sorted(self._hand_geoms))}"
            )

    def _check_object(self, name: str) -> None:
        if name not in self._object_geom:
            names = ", ".join(sorted(self._object_geom)) or "(none)"
            raise DetectorError(f"no object '{name}' in the scene; objects: {names}")

    def _pair_labels(self, pair: tuple[int, int] | NDArray[np.int64]) -> tuple[str, str]:
        """Names of a geom pair's bodies, the robot first, then objects."""
        g1, g2 = sorted((int(pair[0]), int(pair[1])), key=self._rank)
        return self._label(g1), self._label(g2)

    def _label(self, geom: int) -> str:
        """The body's name, or the geom's for geoms on the world body (the floor)."""
        m = self._m
        body = int(m.geom_bodyid[geom])
        if body == 0:
            return m.geom(geom).name or "world"
        return str(m.body(body).name)

    def _rank(self, geom: int) -> int:
        """Order of a pair's names: the robot first, then objects, then the rest of the scene."""
        if geom in self._robot_set:
            return 0
        return 1 if geom in self._object_set else 2

    def _dof_name(self, label: str, k: int) -> str:
        m = self._m
        if label == "qpos":
            jnt = int(np.searchsorted(m.jnt_qposadr, k, side="right")) - 1
        else:
            jnt = int(m.dof_jntid[k])
        return str(m.joint(jnt).name) or f"joint {jnt}"

    def _surface_distance(self, geom: int, point: NDArray[np.float64]) -> float:
        """Distance from ``point`` to the geom's surface; 0 inside (box, sphere, cylinder, else centre).

        Plain float arithmetic on three-vectors (it runs after every physics step while a hand
        carries): ``local = R^T (point - centre)`` in the geom's frame.
        """
        px, py, pz = point.tolist()
        cx, cy, cz = self._geom_xpos[geom].tolist()
        r = self._geom_xmat[geom].tolist()  # row-major R: world = R @ local
        dx, dy, dz = px - cx, py - cy, pz - cz
        lx = r[0] * dx + r[3] * dy + r[6] * dz
        ly = r[1] * dx + r[4] * dy + r[7] * dz
        lz = r[2] * dx + r[5] * dy + r[8] * dz
        sx, sy, sz = self._m.geom_size[geom].tolist()
        kind = self._geom_type[geom]
        if kind == _BOX:
            ox, oy, oz = max(abs(lx) - sx, 0.0), max(abs(ly) - sy, 0.0), max(abs(lz) - sz, 0.0)
            return math.sqrt(ox * ox + oy * oy + oz * oz)
        if kind == _SPHERE:
            return max(0.0, math.sqrt(lx * lx + ly * ly + lz * lz) - sx)
        if kind == _CYLINDER:
            radial = max(0.0, math.hypot(lx, ly) - sx)
            axial = max(0.0, abs(lz) - sy)
            return math.hypot(radial, axial)
        return math.sqrt(lx * lx + ly * ly + lz * lz)
