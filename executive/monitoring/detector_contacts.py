"""The contact check: one geom x geom table of what each contact means in the current phase.

Each pair's code says whether a touch is allowed, a robot self-contact (counted), a
``collision``, a ``fall`` (a robot geom other than the soles on the floor), a ``drop`` (an
object on the floor) or a misgrasp (``drop``: a hand landing on the object it approaches).
``set_phase`` rebuilds the table; ``check`` sums the normal force per flagged pair and
reports the worst one at or above ``collision_force`` (docs/detectors.md, "Allowed contacts").
"""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.monitoring.detector_base import ClosestCall, DetectorThresholds, Failure, Phase
from executive.world.model import World

__all__ = ["ALLOWED", "COLLISION", "ContactCheck", "GeomLabels"]

# Contact codes of the geom x geom table; 0 means allowed and silent.
ALLOWED = 0
_SELF = 1
COLLISION = 2
_FALL = 3  # a non-sole robot geom on the floor
_DROP = 4  # an object on the floor
_MISGRASP = 5  # a hand on the object it approaches to grasp: the jaws missed it
_SEVERITY = {COLLISION: 1, _MISGRASP: 1, _DROP: 2, _FALL: 3}  # several in one step: report the worst


class GeomLabels:
    """Names of geom pairs for reports: each geom's body, the robot's first, then objects'."""

    def __init__(self, world: World) -> None:
        ids = world.ids
        self._m = world.model
        self._robot_set = frozenset(ids.robot_geoms)
        self._object_set = frozenset(ids.object_geoms.values())

    def pair(self, pair: tuple[int, int] | NDArray[np.int64]) -> tuple[str, str]:
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


def _put(a: NDArray[np.int64], b: NDArray[np.int64], code: int, table: NDArray[np.int8]) -> None:
    """Set ``code`` for every geom pair of ``a`` x ``b`` (both ways) in ``table``."""
    table[np.ix_(a, b)] = code
    table[np.ix_(b, a)] = code


class ContactCheck:
    """Verdicts ``fall``, ``drop`` and ``collision`` from the contacts of the last physics step.

    ``codes``: the geom x geom table of the current phase; ``quiet_pairs``: the contact geom
    pairs (bytes) of the last check when all were allowed and silent, which ``check`` skips;
    ``pairs``: the contact geom pairs (bytes, int32 pairs) of the last check, whatever they were;
    ``closest``: the self-contacts and the largest graze seen so far (a :class:`ClosestCall`
    whose clearance fields stay unset); ``labels``: the pair names of reports.
    """

    def __init__(self, world: World, thresholds: DetectorThresholds) -> None:
        m, d, ids = world.model, world.data, world.ids
        self._m, self._d = m, d
        self._force = np.zeros(6)
        self._collision_force = thresholds.collision_force
        self.labels = GeomLabels(world)
        robot = np.array(ids.robot_geoms, dtype=np.int64)
        soles = np.array([g for gs in ids.foot_geoms.values() for g in gs], dtype=np.int64)
        self._hand_geoms: dict[str, NDArray[np.int64]] = {
            side: np.array([g for g in ids.robot_geoms if m.geom_bodyid[g] in set(bodies)], dtype=np.int64)
            for side, bodies in ids.hand_bodies.items()
        }
        self._object_geom = dict(ids.object_geoms)
        self._obstacle_geom = dict(ids.obstacle_geoms)
        self._table = np.array(ids.table_geoms, dtype=np.int64)
        objects = np.array(list(ids.object_geoms.values()), dtype=np.int64)
        obstacles = np.array(list(ids.obstacle_geoms.values()), dtype=np.int64)
        floor = np.array([ids.floor_geom] if ids.floor_geom >= 0 else [], dtype=np.int64)
        self._base_codes = self._code_table(robot, soles, objects, obstacles, floor)
        self.codes = self._base_codes.copy()
        self._code_rows: list[list[int]] = self._base_codes.tolist()
        self.quiet_pairs = b""
        self.pairs = b""
        self.closest = ClosestCall()

    def _code_table(
        self,
        robot: NDArray[np.int64],
        soles: NDArray[np.int64],
        objects: NDArray[np.int64],
        obstacles: NDArray[np.int64],
        floor: NDArray[np.int64],
    ) -> NDArray[np.int8]:
        """The geom x geom contact codes with no phase declared (docs/detectors.md, "Allowed contacts")."""
        m = self._m
        base = np.zeros((m.ngeom, m.ngeom), dtype=np.int8)
        _put(robot, robot, _SELF, base)
        _put(robot, floor, _FALL, base)
        _put(soles, floor, ALLOWED, base)
        for env in (self._table, obstacles, objects):
            _put(robot, env, COLLISION, base)
        _put(objects, floor, _DROP, base)
        _put(objects, obstacles, COLLISION, base)
        _put(objects, self._table, ALLOWED, base)
        _put(objects, objects, ALLOWED, base)
        return base

    def set_phase(self, phase: Phase) -> None:
        """Rebuild the table for ``phase`` (validated by the detector) and forget the quiet pairs."""
        codes = self._base_codes.copy()
        carried, grasping, placing = phase.carried, phase.grasping, phase.placing
        approaching, pushing = phase.approaching, phase.pushing
        if carried is not None:
            side, name = carried
            g = np.array([self._object_geom[name]], dtype=np.int64)
            others = np.array([v for k, v in self._object_geom.items() if k != name], dtype=np.int64)
            _put(g, self._table, COLLISION, codes)
            _put(g, others, COLLISION, codes)
            _put(g, self._hand_geoms[side], ALLOWED, codes)
        if approaching is not None:
            side, name = approaching
            g = np.array([self._object_geom[name]], dtype=np.int64)
            _put(g, self._hand_geoms[side], _MISGRASP, codes)
        if grasping is not None:
            side, name = grasping
            g = np.array([self._object_geom.get(name, self._obstacle_geom.get(name))], dtype=np.int64)
            _put(g, self._hand_geoms[side], ALLOWED, codes)
        if placing is not None:
            g = np.array([self._object_geom[placing]], dtype=np.int64)
            _put(g, self._table, ALLOWED, codes)
        if pushing is not None:
            side, name = pushing
            g = np.array([self._object_geom[name]], dtype=np.int64)
            others = np.array([v for k, v in self._object_geom.items() if k != name], dtype=np.int64)
            _put(g, others, COLLISION, codes)
            _put(g, self._hand_geoms[side], ALLOWED, codes)
        self.codes = codes
        self._code_rows = codes.tolist()
        self.quiet_pairs = b""  # the codes changed: classify the next contacts afresh

    def check(self, t: float) -> Failure | None:
        """The worst forbidden contact at or above ``collision_force``, or None; updates ``closest``."""
        d = self._d
        if not d.ncon:
            self.pairs = b""
            return None
        geom = d.contact.geom
        # The same geom pairs as at the last check, which were all allowed and silent (the
        # common case: feet on the floor, a hand on what it holds): nothing to classify.
        self.pairs = pairs = geom.tobytes()
        if pairs == self.quiet_pairs:
            return None
        codes = self._code_rows
        flagged = [(i, a, b, c) for i, (a, b) in enumerate(geom.tolist()) if (c := codes[a][b])]
        if not flagged:
            self.quiet_pairs = pairs
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
        th = self._collision_force
        worst: tuple[int, float, tuple[int, int]] | None = None
        c = self.closest
        if self_count:
            c = replace(c, self_contacts=c.self_contacts + self_count)
        for key, f in totals.items():
            code = pair_code[key]
            if code == _SELF:
                if f > c.self_force or not c.self_bodies:  # a zero-force touch names its bodies too
                    c = replace(c, self_force=f, self_bodies=self.labels.pair(key))
            elif f >= th:
                if worst is None or (_SEVERITY[code], f) > worst[:2]:
                    worst = (_SEVERITY[code], f, key)
            elif f > c.ignored_force:
                c = replace(c, ignored_force=f, ignored_bodies=self.labels.pair(key), ignored_time=t)
        self.closest = c
        if worst is None:
            return None
        return self._failure(t, worst, pair_code[worst[2]])

    def _failure(self, t: float, worst: tuple[int, float, tuple[int, int]], code: int) -> Failure:
        """The failure of the worst contact: its verdict and a line naming the pair and its force."""
        severity, f, key = worst
        a, b = self.labels.pair(key)
        if code == _MISGRASP:
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
