"""The numerical-stability check: verdict ``unstable`` (a simulation that blew up).

A NaN or inf in ``qpos``, ``qvel`` or ``qacc``, a ``|qvel|`` above ``max_qvel``, or a MuJoCo
warning counter higher than when the check was made. The detector runs it first: with a
broken state the other checks mean nothing.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from executive.monitoring.detector_base import DetectorThresholds, Failure, Phase
from executive.world.model import World

__all__ = ["StabilityCheck"]


class StabilityCheck:
    """Verdict ``unstable``; make it with the world in its start state (the warning counters' base).

    ``last_time``: the simulation time of the detector's last check, which the detector keeps
    up to date; a warning failure reports it when MuJoCo's auto-reset has set the time to 0.
    """

    def __init__(self, world: World, thresholds: DetectorThresholds) -> None:
        m, d = world.model, world.data
        self._m, self._d = m, d
        # Cached views into MjData (its buffers never move).
        self._qpos, self._qvel, self._qacc = d.qpos, d.qvel, d.qacc
        self._warnings = d.warning.number
        self._warnings0 = np.array(self._warnings, dtype=np.int64)
        self._warnings0_bytes = self._warnings.tobytes()
        self._max_qvel = thresholds.max_qvel
        self._max_qvel_sq = thresholds.max_qvel**2
        self.last_time = float(d.time)

    def set_phase(self, phase: Phase) -> None:
        """Nothing depends on the phase."""

    def check(self, t: float) -> Failure | None:
        """An ``unstable`` failure, or None (a byte compare and three dot products when all is well)."""
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
        if abs(float(self._qvel[k])) <= self._max_qvel:
            return None  # a large but finite qpos/qacc sum of squares, or several fast dofs
        return Failure(
            "unstable",
            f"unstable: |qvel[{k}]| ({self._dof_name('qvel', k)}) = {abs(self._qvel[k]):.3g} exceeds "
            f"{self._max_qvel:g} at t={t:.3f} s",
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
        when = max(t, self.last_time)
        return Failure(
            "unstable",
            f"unstable: MuJoCo warning {name} raised {int(raised[k])} time(s) since the detector "
            f"started (last info {info}) at t={when:.3f} s",
            when,
        )

    def _dof_name(self, label: str, k: int) -> str:
        m = self._m
        if label == "qpos":
            jnt = int(np.searchsorted(m.jnt_qposadr, k, side="right")) - 1
        else:
            jnt = int(m.dof_jntid[k])
        return str(m.joint(jnt).name) or f"joint {jnt}"
