"""Reports of a decision: the risk table, its JSON form, and the seed study's two pictures.

* Fig. 5 of Long et al. (2018): the CoM path over the support polygon, with the
  uncertainty circle at the knot of least margin;
* Fig. 6: the minimum robot-obstacle distance over time, with ``d_safety`` marked.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from executive.decision.after_task import chosen_index
from executive.decision.assessment import AlternativeRisk
from executive.decision.physics_check import physics_text
from executive.report.grasp_counts import grasp_counts, grasp_counts_text
from executive.risk.collision import breach_summary
from executive.schema.failure_modes import failure_modes, mode_names
from executive.schema.types import Scenario

__all__ = ["plot_alternatives", "risk_json", "risk_table"]


_POLICY_TEXT = {
    "deny": "the deny policy will refuse it",
    "auto": "the auto policy will approve it",
    "prompt": "an operator must approve it",
}


def _mark(
    scenario: Scenario, alternatives: Sequence[AlternativeRisk], chosen: int | None, approval: str | None
) -> tuple[str, str]:
    """The chosen row's mark and the legend: ``*`` within the threshold; ``!`` above it (needs approval)."""
    threshold = scenario.risk.threshold
    if chosen is None:
        return "*", "* chosen"
    risk = alternatives[chosen].risk
    assert risk is not None
    value = risk.value(scenario.risk.ordering)
    if value <= threshold:
        return "*", "* chosen"
    mode = approval or scenario.approval.mode
    policy = _POLICY_TEXT.get(mode.removeprefix("policy:"), f"{mode} must approve it")
    return "!", (
        f"! lowest {scenario.risk.ordering} ({value:.4g}) but above the threshold {threshold:g}: "
        f"needs approval (approval {mode}: {policy})"
    )


def risk_table(
    scenario: Scenario,
    task_label: str,
    alternatives: Sequence[AlternativeRisk],
    approval: str | None = None,
) -> str:
    """A terminal table in the shape of the seed study's Table 1, the chosen alternative marked.

    ``*`` marks the alternative that would run; when even the lowest is above the
    threshold it is marked ``!`` instead, with a note saying who must approve it:
    ``approval`` (a mode or a channel's name, e.g. ``policy:deny``, ``prompt``) or, by
    default, the scenario's ``approval.mode``.
    """
    ordering = scenario.risk.ordering
    chosen = chosen_index(alternatives, ordering)
    chosen_mark, legend = _mark(scenario, alternatives, chosen, approval)
    head = (
        f"{'':2}{'alternative':<15}"
        + "".join(f"{m.label:>10}" for m in failure_modes())
        + f"{'P(any)':>10}{'seed sum':>10}{'exp. loss':>10}{'min dist':>10}{'min CoM':>9}"
        + (f"{'time loss':>10}{'loss+time':>10}" if scenario.risk.loss_per_second else "")
    )
    lines = [f"task {task_label} (ranked by {ordering}; threshold {scenario.risk.threshold})", head]
    for i, alt in enumerate(alternatives):
        mark = chosen_mark if i == chosen else " "
        if alt.risk is None:
            lines.append(f"{mark} {alt.name:<15}infeasible: {alt.error}")
            continue
        r = alt.risk
        c = r.components
        dist = float(c["collision"].details.get("min_distance", float("nan")))
        margin = float(c["fall"].details.get("min_margin", float("nan")))
        lines.append(
            f"{mark} {alt.name:<15}"
            + "".join(f"{c[m].probability:>10.4f}" for m in mode_names())
            + f"{r.probability:>10.4f}{r.weighted_sum:>10.3f}{r.expected_loss:>10.4f}"
            + f"{dist * 1000:>8.1f}mm{margin * 1000:>7.1f}mm"
            + (
                f"{r.time_loss:>10.4f}{r.expected_loss + r.time_loss:>10.4f}"
                if scenario.risk.loss_per_second
                else ""
            )
        )
        breach = breach_summary(c["collision"])
        if breach is not None:
            near = f" ({breach['bodies']})" if breach["bodies"] else ""
            lines.append(
                f"  {'':<15}breach{near}: P {float(breach['probability']):.4f}, "
                f"exp. loss {float(breach['expected_loss']):.4f}"
            )
        if alt.physics is not None:
            lines.append(f"  {'':<15}{physics_text(alt.physics)}{_fused_text(alt.physics)}")
    counts = grasp_counts(alternatives)
    if counts is not None:
        lines.append(grasp_counts_text(counts))
    lines.append(
        f"{'/'.join(mode_names())}/P(any): probabilities; seed sum: the seed's weighted sum; {legend}"
    )
    return "\n".join(lines)


def _fused_text(physics: dict[str, Any]) -> str:
    """``; analytic->fused collision 0.051->0.049 [0.010, 0.120], ...`` when rollouts ran; a mode
    a dry run refines shows its refined value between (``analytic->dry run->fused``)."""
    modes = physics.get("modes")
    if not modes:
        return ""
    parts = []
    for m, v in modes.items():
        chain = f"{v['analytic']:.3f}"
        if "measured" in v:
            chain += f"->{v['measured']:.3f}"
        if "fused" in v:
            chain += f"->{v['fused']:.3f} [{v['interval'][0]:.3f}, {v['interval'][1]:.3f}]"
        parts.append(f"{m} {chain}")
    stages = ["analytic"]
    stages += ["dry run"] if any("measured" in v for v in modes.values()) else []
    stages += ["fused"] if any("fused" in v for v in modes.values()) else []
    return f"; {'->'.join(stages)} " + ", ".join(parts)


def risk_json(scenario: Scenario, tasks: Sequence[tuple[str, Sequence[AlternativeRisk]]]) -> str:
    """The machine form: ``{"scenario", "tasks": [{"task", "alternatives": [...]}]}``."""
    out: dict[str, Any] = {"scenario": scenario.name, "ordering": scenario.risk.ordering, "tasks": []}
    for label, alternatives in tasks:
        chosen = chosen_index(alternatives, scenario.risk.ordering)
        rows = []
        for i, alt in enumerate(alternatives):
            row: dict[str, Any] = {"name": alt.name, "feasible": alt.feasible, "chosen": i == chosen}
            if i == chosen and alt.risk is not None:  # above the threshold it runs only once approved
                row["needs_approval"] = alt.risk.value(scenario.risk.ordering) > scenario.risk.threshold
            if alt.physics is not None:
                row["physics"] = alt.physics
            if alt.risk is None:
                row["error"] = alt.error
                if alt.binding:  # a move that stalled: the limits that held it back
                    row["binding"] = list(alt.binding)
            else:
                r = alt.risk
                row["risk"] = {
                    **{m: float(r.components[m].probability) for m in mode_names()},
                    "combined": float(r.probability),
                    "combined_bounds": [float(b) for b in r.probability_bounds],
                    "weighted_sum": float(r.weighted_sum),
                    "expected_loss": float(r.expected_loss),
                    "seed": {m: float(r.components[m].seed_score) for m in mode_names()},
                }
                if scenario.risk.loss_per_second:  # the time a way takes costs (ordering loss_and_time)
                    row["risk"]["time_loss"] = float(r.time_loss)
                    row["risk"]["loss_and_time"] = float(r.expected_loss + r.time_loss)
                breach = breach_summary(r.components["collision"])
                if breach is not None:
                    row["risk"]["breach"] = breach
                row["planned_duration_s"] = alt.plan.duration if alt.plan else None
                row["plan_s"] = alt.plan_s
                row["assess_s"] = alt.assess_s
            rows.append(row)
        task: dict[str, Any] = {"task": label, "alternatives": rows}
        counts = grasp_counts(alternatives)
        if counts is not None:  # a task that asked for grasps: how many were pruned and planned
            task["grasps"] = counts
        out["tasks"].append(task)
    return json.dumps(out, indent=2)


def plot_alternatives(
    scenario: Scenario, alternatives: Sequence[AlternativeRisk], polygon: np.ndarray, out_dir: Path
) -> list[Path]:
    """Per feasible alternative: ``<name>_com.png`` (Fig. 5) and ``<name>_distance.png`` (Fig. 6)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    radius = scenario.risk.fall.circle_radius or scenario.risk.fall.sigmas * scenario.uncertainty.com
    for alt in alternatives:
        if alt.risk is None:
            continue
        fall = alt.risk.components["fall"]
        fig, ax = plt.subplots(figsize=(5, 5))
        closed = np.vstack([polygon, polygon[:1]])
        ax.fill(closed[:, 0], closed[:, 1], color="0.9", label="support polygon")
        ax.plot(closed[:, 0], closed[:, 1], color="0.4")
        x, y = fall.traces["com_x"], fall.traces["com_y"]
        ax.plot(x, y, color="C0", label="CoM path (estimate)")
        k = int(np.argmin(fall.traces["margin"]))
        ax.add_patch(
            plt.Circle((x[k], y[k]), radius, color="C3", alpha=0.3, label=f"{radius * 100:.0f} cm circle")
        )
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"{alt.name}: CoM over the support polygon\nP(fall) = {fall.probability:.2e}")
        ax.legend(loc="upper right", fontsize=8)
        path = out_dir / f"{alt.name}_com.png"
        fig.savefig(path, dpi=110, bbox_inches="tight")
        plt.close(fig)
        written.append(path)

        coll = alt.risk.components["collision"]
        fig, ax = plt.subplots(figsize=(7, 3.5))
        ax.plot(coll.times, coll.traces["distance"] * 100, color="C0", label="min distance")
        ax.axhline(scenario.risk.d_safety * 100, color="C3", ls="--", label="d_safety")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("distance to obstacles (cm)")
        ax.set_ylim(bottom=min(0.0, float(coll.traces["distance"].min()) * 100))
        ax.set_title(f"{alt.name}: robot-obstacle distance, P(collision) = {coll.probability:.3f}")
        ax.legend(fontsize=8)
        path = out_dir / f"{alt.name}_distance.png"
        fig.savefig(path, dpi=110, bbox_inches="tight")
        plt.close(fig)
        written.append(path)
    return written
