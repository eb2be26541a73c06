"""Cost of the collision risk model per knot on the book_transfer scene.

Compares, on the same trajectory (300 knots: home -> both hands reaching low over
the table -> home, and a carried book swept past the stack):

- ``assess_collision`` (kinematics, broad phase, coal, seed score, first-order P)
  and ``CollisionModel.profile`` (kinematics, broad phase, coal) per knot;
- "raw": ``mujoco.mj_kinematics`` + ``coal.distance`` on exactly the pairs the broad
  phase let through, with a fresh ``coal.Transform3s`` per geom (the least any
  caller must do for the same answer);
- "all pairs": ``mj_kinematics`` + ``coal.distance`` on every robot-environment pair.

Prints, does not assert. Run: ``python benchmarks/bench_collision.py [repeats]``
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from raw_reference import Knot, raw_distances, record_pairs

from executive.risk.collision import CollisionModel, assess_collision, monte_carlo_collision_probability
from executive.scenario import load
from executive.world.model import World, build

__all__ = ["main", "sweep"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Sweep:
    times: FloatArray
    qpos: FloatArray
    carried: tuple[str, str] | None = None


def _joint(world: World, q: FloatArray, name: str, value: float) -> None:
    q[world.model.jnt_qposadr[world.model.joint(name).id]] = value


def sweep(world: World, knots: int = 300, carried: bool = False) -> Sweep:
    """Home -> reach (hands ~4 cm over the table) -> home; with ``carried``, the book moves past the stack."""
    home = world.home_qpos()
    reach = home.copy()
    for side in ("left", "right"):
        _joint(world, reach, f"{side}_shoulder_pitch", -0.4)
        _joint(world, reach, f"{side}_elbow", -0.2)
    s = 0.5 - 0.5 * np.cos(np.linspace(0.0, 2.0 * np.pi, knots))  # 0 -> 1 -> 0
    qpos = (1.0 - s)[:, None] * home[None, :] + s[:, None] * reach[None, :]
    if carried:
        adr = world.ids.object_qpos["book"]
        y = np.linspace(0.26, -0.26, knots)
        qpos[:, adr] = 0.62 - 0.11 - 0.11 - 0.02  # the book's far end 2 cm short of the stack's near face
        qpos[:, adr + 1] = y
        qpos[:, adr + 2] += 0.08  # lifted 8 cm
    return Sweep(np.linspace(0.0, 6.0, knots), qpos, ("left", "book") if carried else None)


def _time(fn: Callable[[], object], repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return float(best)


def _checked_pairs(model: CollisionModel, path: Sweep) -> list[Knot]:
    """The knots of ``path`` with the (env, robot) geom pairs the broad phase sends to coal."""
    return record_pairs(model, lambda: model.profile(path))


def main(repeats: int = 5) -> None:
    world = build(load("book_transfer"))
    model = CollisionModel(world)
    print(
        f"book_transfer: {len(model.setup.robot_geoms)} robot geoms x {len(model.setup.env_geoms)} env geoms"
    )
    for carried in (False, True):
        path = sweep(world, 300, carried)
        k = len(path.times)
        pairs = _checked_pairs(model, path)
        n_checked = sum(len(p) for _, p in pairs)
        prof = model.profile(path)
        layout = model._layout("book" if carried else None, ())
        every = [(e, r) for e in layout.env_list for r in layout.robot_list]
        all_pairs: list[Knot] = [(row, every) for row in path.qpos]
        kinematics: list[Knot] = [(row, []) for row in path.qpos]
        t_assess = _time(lambda p=path: assess_collision(model, p), repeats)  # type: ignore[misc]
        t_profile = _time(lambda p=path: model.profile(p), repeats)  # type: ignore[misc]
        t_raw = _time(raw_distances(world.model, pairs), repeats)
        t_all = _time(raw_distances(world.model, all_pairs), repeats)
        t_kin = _time(raw_distances(world.model, kinematics), repeats)
        label = "carried book past the stack" if carried else "reach over the table"
        print(f"\n{label}: {k} knots, min distance {float(np.min(prof.distances)) * 100:.2f} cm")
        print(
            f"  pairs checked {prof.pairs_checked} / skipped {prof.pairs_skipped} "
            f"({prof.pairs_checked / k:.1f} coal calls per knot, "
            f"{100 * prof.pairs_skipped / (prof.pairs_checked + prof.pairs_skipped):.0f} % skipped)"
        )
        print(f"  assess_collision   {1e6 * t_assess / k:8.1f} us/knot  {k / t_assess:8.0f} knots/s")
        print(f"  profile            {1e6 * t_profile / k:8.1f} us/knot  {k / t_profile:8.0f} knots/s")
        print(f"  raw (same pairs)   {1e6 * t_raw / k:8.1f} us/knot  ({n_checked} coal.distance calls)")
        print(f"  raw (all pairs)    {1e6 * t_all / k:8.1f} us/knot")
        print(f"  mj_kinematics only {1e6 * t_kin / k:8.1f} us/knot")
        print(
            f"  ratio assess/raw {t_assess / t_raw:.2f}x, profile/raw {t_profile / t_raw:.2f}x "
            f"(target <= 3x); assess/all-pairs {t_assess / t_all:.2f}x"
        )
    path = sweep(world, 300, carried=True)
    t0 = time.perf_counter()
    mc = monte_carlo_collision_probability(model, path, np.random.default_rng(0), samples=2000)
    t_mc = time.perf_counter() - t0
    report = assess_collision(model, path)
    print(
        f"\nMonte Carlo (2000 samples, carried sweep): P = {mc.probability:.4f} +- {mc.stderr:.4f} "
        f"in {t_mc:.2f} s ({mc.coal_calls} coal calls); first order {report.probability:.4f} "
        f"in [{report.probability_bounds[0]:.4f}, {report.probability_bounds[1]:.4f}]"
    )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 5)
