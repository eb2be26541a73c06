"""Falls in physics against the fall model: campaigns of step missions that really fall.

Runs ``executive campaign`` on variants of scenarios/fall_steps.yaml (a walk on its own: the
goal stance and the CoM uncertainty ``uncertainty.com`` vary per variant; the truth robot's CoM
offset is drawn from it), pools the trials and prints, per variant and alternative, the
predicted P(fall) (fused with rollouts, and the analytic model alone: "rollouts off") against the
observed fall rate with its 95% Clopper-Pearson interval, then the pooled ROC AUC and ECE for
falls and the executive's cross-fitted regret (:mod:`executive.validation.regret`), both ways.

    python -m benchmarks.bench_fall_campaign [--trials 8] [--jobs 2] [--out DIR]
        [--set fit|check|all] [--report] [--ablation]

About 6 minutes for the 20 variants with 2 jobs on an idle machine; --report tabulates what --out
holds; --ablation scores the walk's gains on the CoM bias apart. Results: docs/stepping.md, "Falls".
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np
import yaml

from executive.planning.balance_law import STEPPING_GAINS
from executive.planning.timing import concatenate
from executive.risk import fall_assessment
from executive.risk.fall_balance import knot_gains, walk_phases
from executive.scenario.loader import loads
from executive.schema.types import Scenario
from executive.validation.campaign_predictions import predict
from executive.validation.regret import regret, trial_table
from executive.validation.stats import clopper_pearson, expected_calibration_error, roc_auc
from executive.world.model import build

ROOT = Path(__file__).resolve().parents[1]
BASE = ROOT / "scenarios" / "fall_steps.yaml"
SIGMAS = (0.01, 0.02, 0.035, 0.05, 0.08)
#: The goals physics was measured on by hand while the fall model was made (fit) and those kept apart (check).
GOALS = {"fit": ((0.4, 0.0), (0.0, 0.3)), "check": ((0.3, 0.2), (-0.2, 0.0))}


def variants(which: str) -> list[tuple[str, tuple[float, float], float]]:
    """(name, goal, sigma) of the variants of set ``which`` (``fit``, ``check`` or ``all``)."""
    goals = [g for key in ("fit", "check") if which in (key, "all") for g in GOALS[key]]
    return [(f"to{x:+.1f}{y:+.1f}_com{s * 100:.1f}cm", (x, y), s) for x, y in goals for s in SIGMAS]


def run_variant(
    name: str, goal: tuple[float, float], sigma: float, args: argparse.Namespace
) -> list[dict[str, Any]]:
    """One campaign of the variant (its own seeds: independent truths per variant); its trial records."""
    scenario = yaml.safe_load(BASE.read_text())
    scenario["name"] = name
    scenario["trials"]["seed"] = 1000 * (1 + [v[0] for v in variants("all")].index(name))
    scenario["mission"] = [{"step": {"to": list(goal)}}]
    scenario["uncertainty"]["com"] = sigma
    out = Path(args.out) / name
    with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as f:
        yaml.safe_dump(scenario, f)
    command = [sys.executable, "-m", "executive.cli.main", "campaign", f.name, "--trials", str(args.trials)]
    command += ["--jobs", str(args.jobs), "--out", str(out)] + (
        ["--resume"] if (out / "campaign.json").exists() else []
    )
    subprocess.run(command, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines() if line.strip()]


def fall_prediction(record: dict[str, Any], fused: bool) -> float:
    """The record's predicted P(fall): fused with rollouts, or the analytic model's."""
    predicted = record.get("predicted") or {}
    source = predicted if fused else predicted.get("analytic", predicted)
    return float(source.get("fall", 0.0))


def analytic_records(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records with their prediction replaced by the analytic one (the choice without rollouts)."""
    out = []
    for r in records:
        predicted = r.get("predicted")
        out.append({**r, "predicted": {**predicted, **predicted["analytic"]}} if predicted else r)
    return out


def table(runs: dict[str, list[dict[str, Any]]], fused: bool) -> dict[str, Any]:
    """Print the per-variant, per-alternative rows and the pooled scores; return the scores."""
    print(f"\n## {'with rollouts (fused)' if fused else 'rollouts off (analytic model)'}\n")
    print("| variant | alternative | trials | predicted P(fall) | observed falls | observed rate, 95% CI |")
    print("| --- | --- | --- | --- | --- | --- |")
    scores, labels, regrets = [], [], []
    for name, records in runs.items():
        alternatives = sorted({r["alternative"] for r in records})
        for alt in alternatives:
            rows = [r for r in records if r["alternative"] == alt and r["outcome"] != "error"]
            p = [fall_prediction(r, fused) for r in rows]
            falls = [r["outcome"] == "fall" for r in rows]
            low, high = clopper_pearson(sum(falls), len(rows))
            print(f"| {name} | {alt} | {len(rows)} | {np.mean(p):.3f} | {sum(falls)} | "
                  f"{np.mean(falls):.2f} [{low:.2f}, {high:.2f}] |")  # fmt: skip
            scores += p
            labels += falls
        chosen = regret(trial_table(records if fused else analytic_records(records), alternatives))
        regrets.append((chosen.trials, chosen.regret if chosen.regret is not None else 0.0))
    n = sum(t for t, _ in regrets)
    pooled = sum(t * r for t, r in regrets) / n if n else float("nan")
    result = {
        "trials": len(labels),
        "falls": int(sum(labels)),
        "auc": roc_auc(scores, labels),
        "ece": expected_calibration_error(scores, labels),
        "mean_predicted": float(np.mean(scores)),
        "observed_rate": float(np.mean(labels)),
        "regret": pooled,
    }
    print(
        f"\nfalls {result['falls']} of {result['trials']} trials; mean predicted "
        f"{result['mean_predicted']:.3f}, observed {result['observed_rate']:.3f}; AUC {result['auc']:.3f}; "
        f"ECE {result['ece']:.3f}; cross-fitted regret (any failure, pooled over variants) "
        f"{pooled * 100:+.1f} points"
    )
    return result


def scenario_of(name: str, goal: tuple[float, float], sigma: float) -> Scenario:
    """The variant's scenario (as :func:`run_variant` writes it)."""
    data = yaml.safe_load(BASE.read_text())
    data["name"] = name
    data["mission"] = [{"step": {"to": list(goal)}}]
    data["uncertainty"]["com"] = sigma
    return loads(yaml.safe_dump(data))


def ablation(runs: dict[str, list[dict[str, Any]]], which: str) -> None:
    """The analytic P(fall) of each variant's plans under three gains on the CoM bias in a walk,
    scored on the same trials: none (the model before: the bias as it is at every knot), the
    residual ``r`` the pelvis shift leaves (on one foot too), and the model (``r`` on two feet,
    the law's CoP ``(1 + convergence) r`` on one; :mod:`executive.risk.fall_balance`)."""
    gains: dict[str, Callable[..., Any]] = {
        "none": lambda world, knots, *a: np.ones(len(knots.times)),
        "residual r": lambda *a: knot_gains(*a[:3], dataclasses.replace(STEPPING_GAINS, convergence=0.0)),
        "model: r, (1 + convergence) r on one foot": knot_gains,
    }
    print("\n## gain on the CoM bias in a walk: ablation (analytic, rollouts off)\n")
    print("| gain | AUC | ECE | mean predicted | observed |")
    print("| --- | --- | --- | --- | --- |")
    plans = {}
    for name, goal, sigma in variants(which):
        if name in runs:
            scenario = scenario_of(name, goal, sigma)
            plans[name] = (scenario, {a: predict(scenario, 0, a) for a in ("left_first", "right_first")})
    for label, gain in gains.items():
        scores, labels = [], []
        for name, (scenario, predicted) in plans.items():
            with mock.patch.object(fall_assessment, "knot_gains", gain):
                p = {a: _fall(scenario, x) for a, x in predicted.items()}
            for r in runs[name]:
                if r["outcome"] != "error" and p[r["alternative"]] is not None:
                    scores.append(float(p[r["alternative"]]))
                    labels.append(r["outcome"] == "fall")
        auc, ece = roc_auc(scores, labels), expected_calibration_error(scores, labels)
        print(f"| {label} | {auc:.3f} | {ece:.3f} | {np.mean(scores):.3f} | {np.mean(labels):.3f} |")


def _fall(scenario: Scenario, prediction: Any) -> float | None:
    """The analytic P(fall) of a prediction's plan (None: it did not plan)."""
    if not prediction.feasible:
        return None
    world = build(scenario)
    whole = concatenate(prediction.plan.ordered_trajectories(), prediction.plan.name)
    walks = walk_phases(prediction.plan)
    return fall_assessment.assess_fall(
        world, whole, scenario.risk, scenario.uncertainty, None, walks
    ).probability


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=8)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", default=str(ROOT / "runs" / "bench_fall_campaign"))
    parser.add_argument("--set", choices=("fit", "check", "all"), default="all")
    parser.add_argument("--report", action="store_true", help="only tabulate the variants already in --out")
    parser.add_argument(
        "--ablation", action="store_true", help="also score the model without the walk's gains"
    )
    args = parser.parse_args()
    runs = {}
    for name, goal, sigma in variants(args.set):
        trials = Path(args.out) / name / "trials.jsonl"
        if args.report:
            if trials.exists():
                runs[name] = [json.loads(line) for line in trials.read_text().splitlines() if line.strip()]
            continue
        runs[name] = run_variant(name, goal, sigma, args)
        print(f"{name}: {len(runs[name])} records", file=sys.stderr, flush=True)
    summary = {"fused": table(runs, fused=True), "analytic": table(runs, fused=False)}
    (Path(args.out) / "summary.json").write_text(json.dumps(summary, indent=1))
    if args.ablation:
        ablation(runs, args.set)


if __name__ == "__main__":
    main()
