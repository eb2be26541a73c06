"""The closest call's clearance: the smallest distance of a pair that may not touch now.

Not a failure check: the detector calls :meth:`Clearance.update` every ``distance_stride``
checks. A vectorised lower bound (a mover's bounding sphere vs. the static boxes in their
own frames, bounding spheres for moving things) selects the pairs that could beat the best
so far, and ``mujoco.mj_geomDistance`` gives their exact distance.
"""

from __future__ import annotations

import math
from dataclasses import replace

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.monitoring.detector_base import ClosestCall, DetectorThresholds, Phase
from executive.monitoring.detector_contacts import COLLISION, ContactCheck
from executive.world.model import World

__all__ = ["Clearance"]


class Clearance:
    """The smallest clearance between the movers (robot, objects) and what they may not touch.

    The pairs come from ``contacts``' code table (the forbidden ones of the current phase; the
    floor is left out: its distance says nothing). ``closest``: a :class:`ClosestCall` whose
    clearance fields (``distance``, ``distance_bodies``, ``distance_time``) hold the best so far.
    """

    def __init__(self, world: World, thresholds: DetectorThresholds, contacts: ContactCheck) -> None:
        ids = world.ids
        self._m, self._d = world.model, world.data
        self._geom_xpos = world.data.geom_xpos
        self._horizon = thresholds.clearance_horizon
        self._contacts = contacts
        self.closest = ClosestCall()
        robot = np.array(ids.robot_geoms, dtype=np.int64)
        objects = np.array(list(ids.object_geoms.values()), dtype=np.int64)
        obstacles = np.array(list(ids.obstacle_geoms.values()), dtype=np.int64)
        table = np.array(ids.table_geoms, dtype=np.int64)
        self._setup(np.concatenate([robot, objects]), np.concatenate([table, obstacles, objects]))

    def _setup(self, movers: NDArray[np.int64], candidates: NDArray[np.int64]) -> None:
        """The broad phase: moving geoms (robot, objects) vs scene things.

        Things welded to the world (table, obstacles) are boxes whose frames never move: a mover's
        centre is taken into all of them with one matrix product. Things that move (objects, any
        obstacle that is not static) use their bounding spheres.
        """
        m, d = self._m, self._d
        self._movers = movers
        is_box = m.geom_type[candidates] == mujoco.mjtGeom.mjGEOM_BOX
        welded = m.body_weldid[m.geom_bodyid[candidates]] == 0
        static = candidates[is_box & welded]
        moving = candidates[~(is_box & welded)]
        self._things = np.concatenate([static, moving])
        self._moving = moving
        n_static, n_moving = len(static), len(moving)
        rot = d.geom_xmat[static].reshape(-1, 3, 3)
        eye = np.broadcast_to(np.eye(3), (n_moving, 3, 3))
        self._frames = np.concatenate([rot, eye]).transpose(1, 0, 2).reshape(3, -1)
        self._origins = np.concatenate(
            [np.einsum("ki,kij->kj", d.geom_xpos[static], rot).reshape(-1), np.zeros(3 * n_moving)]
        )
        self._half = np.concatenate([m.geom_size[static].reshape(-1), np.zeros(3 * n_moving)])
        # Sums the three squared components of each thing's block: (3 K) x K.
        self._sum = np.kron(np.eye(n_static + n_moving), np.ones((3, 1)))
        rb_movers = m.geom_rbound[movers][:, None]
        self._base_offset = np.concatenate(
            [np.broadcast_to(-rb_movers, (len(rb_movers), n_static)), -rb_movers - m.geom_rbound[moving]],
            axis=1,
        )
        self._n_static = n_static
        self._offset = self._base_offset
        self._best = math.nan
        self._limit_sq = np.zeros_like(self._base_offset)

    def set_phase(self, phase: Phase) -> None:
        """Take the forbidden pairs from the contact table (call after the contact check's ``set_phase``)."""
        # +inf on the pairs that may touch, so they never beat the best clearance.
        forbidden = self._contacts.codes[np.ix_(self._movers, self._things)] == COLLISION  # not a misgrasp
        forbidden &= self._movers[:, None] != self._things[None, :]
        self._offset = np.where(forbidden, self._base_offset, np.inf)
        self._best = math.nan  # recompute the squared thresholds at the next clearance

    def update(self, t: float) -> None:
        """Smallest clearance of a forbidden pair, if below the best so far (vectorised broad phase).

        Lower bound per pair: distance from the moving geom's bounding sphere to the other
        geom's oriented box (its bounding sphere when it is not a box); exact distances
        (``mj_geomDistance``) only for pairs whose bound beats the best clearance so far.
        """
        best = min(self.closest.distance, self._horizon)
        if best != self._best:  # squared thresholds follow the best clearance so far
            self._best = best
            self._limit_sq = np.square(np.maximum(best - self._offset, 0.0))
        # Every mover's centre in every thing's frame with one product; moving things (objects)
        # have an identity frame at their current centre and a zero half size (a sphere).
        self._origins[self._n_static * 3 :] = self._geom_xpos[self._moving].reshape(-1)
        local = self._geom_xpos[self._movers] @ self._frames
        local -= self._origins
        np.abs(local, out=local)
        local -= self._half
        np.maximum(local, 0.0, out=local)
        local *= local
        rows, cols = np.nonzero(local @ self._sum < self._limit_sq)
        if not rows.size:
            return
        movers_ids, things = self._movers, self._things
        best_pair: tuple[int, int] | None = None
        for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
            g1, g2 = int(movers_ids[r]), int(things[c])
            dist = float(mujoco.mj_geomDistance(self._m, self._d, g1, g2, best, None))
            if dist < best:
                best, best_pair = dist, (g1, g2)
        if best_pair is not None:
            self.closest = replace(
                self.closest,
                distance=best,
                distance_bodies=self._contacts.labels.pair(best_pair),
                distance_time=t,
            )
