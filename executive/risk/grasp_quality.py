"""How good a grasp that has been made is: its grasp matrix's measures, and a shake test.

:func:`grasp_quality` measures a grasp by the singular values of its grasp matrix
(:func:`grasp_from_physics` for the contacts MuJoCo found); :func:`shake_test` checks it in
physics by oscillating the wrist.

Usage::

    q = grasp_from_physics(world, world.data, "left", "book")
    q.sigma_min, q.isotropy
    shake_test(world, "left", "book", amplitude_rad=0.2, frequency_hz=2.0, duration_s=1.0).held
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, NamedTuple

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from executive.world.model import World

__all__ = [
    "CONTACT_MODELS",
    "ContactModel",
    "GraspQuality",
    "ShakeResult",
    "grasp_from_physics",
    "grasp_matrix",
    "grasp_quality",
    "shake_test",
    "skew",
]

FloatArray = NDArray[np.float64]
ContactModel = Literal["frictionless", "hard_finger", "point_with_friction", "soft_finger"]
#: Columns of the contact-frame wrench (f_n, f_t, f_o, m_n, m_t, m_o) each contact model transmits.
CONTACT_MODELS: dict[str, tuple[int, ...]] = {
    "frictionless": (0,),
    "hard_finger": (0, 1, 2),
    "point_with_friction": (0, 1, 2),  # the Handbook's name for the hard-finger model
    "soft_finger": (0, 1, 2, 3),
}


# --- grasp matrix ---------------------------------------------------------------------------


def skew(v: ArrayLike) -> FloatArray:
    """S(v) with S(v) x = v x x."""
    x, y, z = np.asarray(v, dtype=float).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def grasp_matrix(
    contact_points: ArrayLike,
    contact_frames: ArrayLike,
    object_centre: ArrayLike,
    model: ContactModel = "hard_finger",
) -> FloatArray:
    """Grasp matrix G (6 x m): object wrench about the centre = G @ stacked contact wrenches.

    contact_frames[i] is R_i, columns (normal into the object, tangent, tangent) in the world;
    G_i = [[R_i, 0], [S(p_i - c) R_i, R_i]] with the contact model's columns kept: frictionless
    point [f_n], hard finger = point contact with friction [f_n, f_t, f_o], soft finger
    [f_n, f_t, f_o, m_n]. Prattichizzo & Trinkle, Springer Handbook of Robotics, 2nd ed., ch. 38
    "Grasping" (ch. 28 in the 1st ed.); Murray, Li & Sastry 1994, ch. 5.
    """
    if model not in CONTACT_MODELS:
        raise ValueError(
            f"grasp_matrix: contact model must be one of {sorted(CONTACT_MODELS)}, got {model!r}"
        )
    points = np.asarray(contact_points, dtype=float).reshape(-1, 3)
    frames = np.asarray(contact_frames, dtype=float).reshape(-1, 3, 3)
    if len(points) != len(frames):
        raise ValueError(f"grasp_matrix: {len(points)} points but {len(frames)} frames")
    centre = np.asarray(object_centre, dtype=float).reshape(3)
    cols = list(CONTACT_MODELS[model])
    blocks = []
    for p, rot in zip(points, frames, strict=True):
        full = np.zeros((6, 6))
        full[:3, :3] = rot
        full[3:, :3] = skew(p - centre) @ rot
        full[3:, 3:] = rot
        blocks.append(full[:, cols])
    return np.hstack(blocks) if blocks else np.zeros((6, 0))


@dataclass(frozen=True)
class GraspQuality:
    """A grasp's contacts, its grasp matrix and the singular-value measures of it."""

    points: FloatArray  # (n, 3)
    frames: FloatArray  # (n, 3, 3), columns normal (into the object), tangents
    matrix: FloatArray  # (6, m)
    singular_values: FloatArray  # (6,), descending, zero-padded when m < 6
    sigma_min: float
    isotropy: float  # sigma_min / sigma_max (0 for no contacts)

    @property
    def contacts(self) -> int:
        return len(self.points)


def grasp_quality(
    contact_points: ArrayLike,
    contact_frames: ArrayLike,
    object_centre: ArrayLike,
    model: ContactModel = "hard_finger",
) -> GraspQuality:
    """Grasp matrix and its measures: sigma_min(G) (Li & Sastry 1988) and the isotropy
    sigma_min / sigma_max (Kim et al. 2004; the inverse of the condition number the seed's Q
    relates to)."""
    points = np.asarray(contact_points, dtype=float).reshape(-1, 3)
    frames = np.asarray(contact_frames, dtype=float).reshape(-1, 3, 3)
    g = grasp_matrix(points, frames, object_centre, model)
    sv = np.zeros(6)
    if g.shape[1]:
        s = np.linalg.svd(g, compute_uv=False)
        sv[: len(s)] = s
    sigma_max = float(sv[0])
    return GraspQuality(
        points=points,
        frames=frames,
        matrix=g,
        singular_values=sv,
        sigma_min=float(sv[-1]),
        isotropy=float(sv[-1] / sigma_max) if sigma_max > 0.0 else 0.0,
    )


def grasp_from_physics(
    world: World, data: mujoco.MjData, side: str, obj: str, model: ContactModel = "hard_finger"
) -> GraspQuality:
    """Grasp quality of the current contacts between the ``side`` hand's geoms and ``obj``'s geom.

    MuJoCo's contact frame rows are (normal, tangent, tangent) with the normal pointing from
    geom1 to geom2; it is flipped (with one tangent, keeping a right-handed frame) so the
    normal points into the object. The centre is the object's centre of mass (data.xipos).
    """
    hand = set(world.ids.hand_bodies[side])
    obj_geom = world.ids.object_geoms[obj]
    gbody = world.model.geom_bodyid
    points, frames = [], []
    for i in range(data.ncon):
        g1, g2 = int(data.contact.geom[i][0]), int(data.contact.geom[i][1])
        if g2 == obj_geom and int(gbody[g1]) in hand:
            sign = 1.0
        elif g1 == obj_geom and int(gbody[g2]) in hand:
            sign = -1.0
        else:
            continue
        rows = data.contact.frame[i].reshape(3, 3)
        rot = np.column_stack([sign * rows[0], sign * rows[1], rows[2]])
        points.append(data.contact.pos[i].copy())
        frames.append(rot)
    centre = data.xipos[world.ids.object_bodies[obj]]
    return grasp_quality(np.array(points).reshape(-1, 3), np.array(frames).reshape(-1, 3, 3), centre, model)


# --- shake validation -----------------------------------------------------------------------


class ShakeResult(NamedTuple):
    """Outcome of :func:`shake_test`: whether the object stayed in the hand, and its largest drift (m)."""

    held: bool
    drift_m: float


def _actuator_of(model: mujoco.MjModel, joint: int) -> int:
    for a in range(model.nu):
        if (
            model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT
            and int(model.actuator_trnid[a, 0]) == joint
        ):
            return a
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, joint)
    raise ValueError(f"shake_test: joint '{name}' has no actuator")


def shake_test(
    world: World,
    side: str,
    obj: str,
    *,
    amplitude_rad: float,
    frequency_hz: float,
    duration_s: float,
    tolerance: float = 0.02,
    joints: tuple[str, ...] | None = None,
) -> ShakeResult:
    """Shake a grasped object by oscillating the wrist servos' targets (the seed's sinusoidal
    excitation); steps ``world.data``.

    The caller has the object grasped in ``world.data``. Each joint's position actuator
    target becomes q0 + amplitude sin(2 pi f t) (clipped to its ctrlrange) for
    ``duration_s``; drift_m is the largest displacement of the object's centre in the hand
    site's frame from where it was at the start; held = drift_m <= tolerance. joints None:
    the arm's last two joints (the wrist). Targets are restored at the end.
    """
    if amplitude_rad < 0.0 or frequency_hz <= 0.0 or duration_s <= 0.0 or tolerance <= 0.0:
        raise ValueError(
            "shake_test: need amplitude >= 0, frequency > 0, duration > 0 and tolerance > 0, got "
            f"{amplitude_rad}, {frequency_hz}, {duration_s}, {tolerance}"
        )
    model, data = world.model, world.data
    names = joints if joints is not None else world.profile.arms[side].joints[-2:]
    acts = []
    for name in names:
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if j < 0:
            raise ValueError(f"shake_test: no joint '{name}' in the model")
        acts.append(_actuator_of(model, int(j)))
    act_idx = np.array(acts, dtype=int)
    ctrl0 = data.ctrl[act_idx].copy()
    lo, hi = model.actuator_ctrlrange[act_idx, 0], model.actuator_ctrlrange[act_idx, 1]
    limited = model.actuator_ctrllimited[act_idx].astype(bool)
    site = world.ids.hand_sites[side]
    body = world.ids.object_bodies[obj]
    mujoco.mj_forward(model, data)

    def in_hand() -> FloatArray:
        rot = data.site_xmat[site].reshape(3, 3)
        return np.asarray(rot.T @ (data.xpos[body] - data.site_xpos[site]), dtype=float)

    reference = in_hand()
    t0 = float(data.time)
    steps = round(duration_s / model.opt.timestep)
    drift = 0.0
    try:
        for _ in range(steps):
            target = ctrl0 + amplitude_rad * np.sin(2.0 * np.pi * frequency_hz * (data.time - t0))
            data.ctrl[act_idx] = np.where(limited, np.clip(target, lo, hi), target)
            mujoco.mj_step(model, data)
            drift = max(drift, float(np.linalg.norm(in_hand() - reference)))
            if not np.isfinite(drift):
                break
    finally:
        data.ctrl[act_idx] = ctrl0
    return ShakeResult(held=bool(np.isfinite(drift) and drift <= tolerance), drift_m=float(drift))
