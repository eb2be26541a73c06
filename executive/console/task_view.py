"""One task's decision on the console's page: the ranked risk table and each alternative's planned motion.

A :class:`TaskView` is a folder of the panel: the risk table of the task's last decision
(:mod:`executive.console.risk_table`), what physics said of each alternative, and per feasible
alternative with a plan a sub-folder with its facts (duration, closest approach, least CoM
margin) and a time slider that puts the ghost (:class:`executive.console.ghost.GhostView`)
where the plan has the robot at that time; a button jumps to the closest approach.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from executive.console.ghost import GhostView, PlannedMotion
from executive.console.risk_table import physics_table, ranked, risk_table

if TYPE_CHECKING:
    import viser

__all__ = ["TaskView", "motion_facts"]

SLIDER_STEP_S = 0.05


def _snap(t: float) -> float:
    """``t`` on the slider's steps."""
    return round(round(t / SLIDER_STEP_S) * SLIDER_STEP_S, 6)


def motion_facts(motion: PlannedMotion) -> str:
    """One paragraph: how long the motion is, where it passes closest, how near the CoM gets to the edge."""
    parts = [f"planned motion {motion.duration:.1f} s"]
    if motion.closest is not None:
        parts.append(motion.closest.text())
    if motion.min_margin is not None:
        x, y, margin, _ = motion.min_margin
        parts.append(f"least CoM margin {margin * 1000:.0f} mm at ({x:.3f}, {y:.3f})")
    return "; ".join(parts)


class TaskView:
    """The folder of one task's decision.

    Args:
        server: the console's viser server.
        ghost: where planned motions are shown (None: rows only, e.g. a run folder's).
        label: the folder's title (the task).
        order: where the folder sits in the panel.
    """

    def __init__(self, server: viser.ViserServer, ghost: GhostView | None, label: str, order: float) -> None:
        self.server, self.ghost, self.label = server, ghost, label
        self.folder = server.gui.add_folder(label, order=order)
        self._widgets: list[Any] = []
        self.sliders: dict[str, Any] = {}
        self.motions: dict[str, PlannedMotion] = {}

    def show(
        self,
        rows: Sequence[Mapping[str, Any]],
        ordering: str,
        threshold: float,
        motions: Mapping[str, PlannedMotion] | None = None,
        note: str = "",
    ) -> None:
        """Lay the decision out anew: ``rows`` (:mod:`executive.console.risk_table`), motions by name."""
        for widget in self._widgets:
            widget.remove()
        self._widgets, self.sliders, self.motions = [], {}, dict(motions or {})
        gui = self.server.gui
        with self.folder:
            if note:
                self._widgets.append(gui.add_markdown(note))
            self._widgets.append(gui.add_markdown(risk_table(rows, ordering, threshold)))
            physics = physics_table(rows)
            if physics:
                self._widgets.append(
                    gui.add_markdown(
                        "**physics check** (per mode: analytic → fused [interval])\n\n" + physics
                    )
                )
            for row in ranked(rows):
                motion = self.motions.get(str(row["name"]))
                if motion is not None:
                    self._alternative(motion)
        first = next(
            (self.motions[str(r["name"])] for r in ranked(rows) if str(r["name"]) in self.motions), None
        )
        if first is not None and self.ghost is not None:  # the lowest, where it passes closest
            t = _snap(first.closest.time) if first.closest is not None else 0.0
            self.ghost.show(first, t)
            self.sliders[first.name].value = t

    def _alternative(self, motion: PlannedMotion) -> None:
        gui = self.server.gui
        folder = gui.add_folder(f"{motion.name}: planned motion", expand_by_default=True)
        self._widgets.append(folder)
        with folder:
            gui.add_markdown(motion_facts(motion))
            slider = gui.add_slider(
                f"{motion.name} [s]",
                min=0.0,
                max=max(SLIDER_STEP_S, round(motion.duration, 2)),
                step=SLIDER_STEP_S,
                initial_value=0.0,
                hint="scrub the planned motion: the ghost robot follows",
            )
            slider.on_update(lambda _: self._scrub(motion, float(slider.value)))
            self.sliders[motion.name] = slider
            if motion.closest is not None:
                jump = gui.add_button(f"{motion.name}: go to the closest approach", color="gray")
                closest = _snap(motion.closest.time)
                jump.on_click(lambda _: setattr(slider, "value", closest))

    def _scrub(self, motion: PlannedMotion, t: float) -> None:
        if self.ghost is not None:
            self.ghost.show(motion, t)
