"""Failure detectors: decide, from the TRUTH world's physics, what happened during a behaviour.

:class:`FailureDetector` looks only at the MuJoCo state after each ``mj_step`` and at the
phase the executing behaviour declares (``set_phase``), independent of the planner and the
risk models. It runs one check per verdict family in a fixed order (stability, fall, hold,
contacts, foot slip: the first failure of a step wins) and latches the first failure; it also keeps
the closest call for the report. The verdicts, what is allowed and what each check costs:
docs/detectors.md.
"""

from __future__ import annotations

from dataclasses import replace

from executive.monitoring.detector_base import (
    Check,
    ClosestCall,
    DetectorError,
    DetectorThresholds,
    Failure,
    Phase,
    require_object,
    require_side,
)
from executive.monitoring.detector_clearance import Clearance
from executive.monitoring.detector_contacts import ContactCheck
from executive.monitoring.detector_fall import FallCheck
from executive.monitoring.detector_foot_slip import FootSlip, FootSlipCheck
from executive.monitoring.detector_objects import HoldCheck, check_placement
from executive.monitoring.detector_stability import StabilityCheck
from executive.world.model import World

__all__ = [
    "Check",
    "ClosestCall",
    "DetectorError",
    "DetectorThresholds",
    "Failure",
    "FailureDetector",
    "FootSlip",
    "Phase",
]


class FailureDetector:
    """Watches one execution in a truth world; call :meth:`check` after every ``mj_step``.

    Make one detector per execution, with the world in its start state: the MuJoCo warning
    counters are taken at construction (and the start pelvis height, ``start_height``, for
    the report); the fall limits are the robot's safe posture's unless ``thresholds`` sets them
    (``standing_height``, ``pelvis_drop`` and ``trunk_tilt_deg`` are those in force); the foot
    slip limits are the robot's sole's unless it sets them (``foot_slip``, ``foot_slip_yaw_deg``
    and ``foot_slip_load`` are those in force).
    ``distance_stride``: compute the closest clearance every this many checks (0: never).
    """

    def __init__(
        self, world: World, thresholds: DetectorThresholds | None = None, *, distance_stride: int = 10
    ) -> None:
        self.world = world
        self.thresholds = th = thresholds or DetectorThresholds()
        d, ids = world.data, world.ids
        self._d = d
        self._stability = StabilityCheck(world, th)
        fall = FallCheck(world, th)
        self._hold = HoldCheck(world, th)
        self._contacts = ContactCheck(world, th)
        self._near = Clearance(world, th, self._contacts)
        self._slip = FootSlipCheck(world, th, self._contacts)  # reads the contact check's pairs
        checks: tuple[Check, ...] = (self._stability, fall, self._hold, self._contacts, self._slip)
        self._checks = checks
        self._check_fns = tuple(c.check for c in checks)  # the per-step loop, in verdict order
        self.start_height = float(d.xpos[ids.base_body][2])
        #: m: the pelvis height of the standing keyframe, which the pelvis limit is measured from.
        self.standing_height = fall.standing_height
        #: m below standing and deg from vertical beyond which the robot has fallen.
        self.pelvis_drop, self.trunk_tilt_deg = fall.pelvis_drop, fall.trunk_tilt_deg
        #: m a standing foot's sole may slide and deg it may turn before it has slipped, and the
        #: share of the robot's weight it carries for that to count.
        self.foot_slip, self.foot_slip_yaw_deg = self._slip.slide, self._slip.turn_deg
        self.foot_slip_load = self._slip.load
        self._feet = frozenset(self._slip.sides)
        self._sides = frozenset(ids.hand_bodies)
        self._objects = frozenset(ids.object_geoms)
        self._obstacles = frozenset(ids.obstacle_geoms)
        self._stride = max(0, int(distance_stride))
        self._n_checks = 0
        self._clearance_at = 0  # _n_checks at the last clearance
        self._failure: Failure | None = None
        self._phase = Phase()
        self.set_phase()

    # --- phase ---------------------------------------------------------------------------

    def set_phase(
        self,
        *,
        carried: tuple[str, str] | None = None,
        grasping: tuple[str, str] | None = None,
        placing: str | None = None,
        approaching: tuple[str, str] | None = None,
        pushing: tuple[str, str] | None = None,
        support: tuple[str, ...] | None = None,
    ) -> None:
        """Declare what the behaviour does now; each call replaces the previous phase.

        carried: (side, object) the hand holds now; grasping: (side, object) the hand may
        touch now (closing on it), or (side, obstacle) it presses; placing: the object allowed
        to touch the table now;
        approaching: (side, object) the open hand is moving onto to grasp: a forceful touch
        now is a misaligned grasp (mode ``drop``), not a collision; pushing: (side, object) the
        hand slides along the table: that hand may touch it, it may touch the table and slide
        away from the hand (no hold distance), and it touching another object is a collision.
        A handover carries with one side and grasps with the other. support: the feet meant to
        stand still where they touch the floor (a step's stance foot on one foot); None: every
        foot (any motion but a step's).

        Raises:
            DetectorError: a side, a foot or an object the world does not have.
        """
        for pair in (carried, grasping, approaching, pushing):
            if pair is not None:
                require_side(pair[0], self._sides)
                if pair is not grasping or pair[1] not in self._obstacles:  # a press touches an obstacle
                    require_object(pair[1], self._objects)
        if placing is not None:
            require_object(placing, self._objects)
        for foot in support or ():
            if foot not in self._feet:
                raise DetectorError(f"no foot '{foot}'; the robot has: {', '.join(sorted(self._feet))}")
        phase = Phase(
            carried, grasping, placing, approaching, pushing, None if support is None else tuple(support)
        )
        for c in self._checks:
            c.set_phase(phase)
        self._near.set_phase(phase)  # after the contact check: it reads the new contact table
        self._phase = phase

    @property
    def phase(self) -> dict[str, object]:
        """The phase last set (for logging)."""
        p = self._phase
        return {
            "carried": p.carried,
            "grasping": p.grasping,
            "placing": p.placing,
            "approaching": p.approaching,
            "pushing": p.pushing,
            "support": p.support,
        }

    # --- results -------------------------------------------------------------------------

    @property
    def failure(self) -> Failure | None:
        """The first failure seen, or None."""
        return self._failure

    @property
    def closest_call(self) -> ClosestCall:
        """The smallest clearance, largest ignored contact and self-contacts seen so far."""
        near = self._near.closest
        return replace(
            self._contacts.closest,
            distance=near.distance,
            distance_bodies=near.distance_bodies,
            distance_time=near.distance_time,
        )

    @property
    def largest_slip(self) -> tuple[FootSlip, FootSlip]:
        """The largest slide (m) and the largest turn (rad) of a standing foot seen so far, each
        with its foot and time: how near the feet came to a slip."""
        return self._slip.largest

    def foot_slip_now(self, side: str) -> FootSlip | None:
        """The ``side`` foot's slip so far, from its contacts now (how far its points on the
        floor slid, how much it turned, how fast, under what share of the weight), or None while
        it does not stand (lifted, or not a support foot of the phase).

        Raises:
            DetectorError: the robot has no ``side`` foot.
        """
        if side not in self._feet:
            raise DetectorError(f"no foot '{side}'; the robot has: {', '.join(sorted(self._feet))}")
        return self._slip.measure(side, float(self._d.time))

    @property
    def slipped(self) -> FootSlip | None:
        """The last foot slip found (side, distance, turn, speed, time), or None."""
        return self._slip.slipped

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
        t = float(self._d.time)
        found = None
        for check in self._check_fns:
            found = check(t)
            if found is not None:
                break
        self._n_checks += 1
        if found is None and self._stride and self._n_checks - self._clearance_at >= self._stride:
            self._clearance_at = self._n_checks
            self._clearance(t)
        self._stability.last_time = t
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
        stability = self._stability
        if t < stability.last_time:  # MuJoCo's auto-reset after a bad state: the full check sees it
            return self.check()
        self._n_checks += 1
        stability.last_time = t
        contacts = self._contacts
        if not d.ncon or d.contact.geom.tobytes() == contacts.quiet_pairs:  # the contact check's fast path
            return None
        found = contacts.check(t)
        if found is not None:
            self._failure = found
        return found

    def _clearance(self, t: float) -> None:
        """Update the closest call's clearance (every ``distance_stride`` checks)."""
        self._near.update(t)

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

        Raises:
            DetectorError: ``obj`` is no object of the scene.
        """
        require_object(obj, self._objects)
        failure = check_placement(self.world, self.thresholds, obj, target_xy, target_yaw, yaw_symmetry)
        if failure is not None and self._failure is None:
            self._failure = failure
        return failure
