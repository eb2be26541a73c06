"""Fidelity suites: seeded valid scene variants, the cross-fitted regret and its test, end to end.

References: MuJoCo's own geometry (mj_geomDistance, geom poses) for the variants' validity;
hand-computed tables, a closed form of the in-sample bias (the expected minimum of iid
binomials) and Monte Carlo for the regret; direct binomial sums for the sign test.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest

from executive.cli.main import main
from executive.decision.physics_check import with_rollouts
from executive.scenario import load
from executive.schema.types import Scenario
from executive.validation.regret import (
    TrialTable,
    newcombe_interval,
    regret,
    sign_test,
    trial_table,
)
from executive.validation.variants import (
    Variant,
    VariationRanges,
    base_document,
    make_variant,
    scene_problem,
    write_variant,
)
from executive.world.model import build

RANGES = VariationRanges()


@pytest.fixture(scope="module")
def base() -> Scenario:
    return load("book_transfer")


@pytest.fixture(scope="module")
def variants(base: Scenario) -> list[Variant]:
    document = base_document(base)
    return [make_variant(base, document, 3, k) for k in range(24)]


# --- variants -----------------------------------------------------------------------------------


def test_variants_are_seeded_and_reproducible(base: Scenario, variants: list[Variant]) -> None:
    document = base_document(base)
    again = make_variant(base, document, 3, 5)
    assert again.document == variants[5].document and again.redraws == variants[5].redraws
    assert make_variant(base, document, 4, 5).document != variants[5].document  # another seed
    assert len({json.dumps(v.document, sort_keys=True) for v in variants}) == len(variants)


def test_variants_stay_in_the_documented_ranges(base: Scenario, variants: list[Variant]) -> None:
    (book,), (stack,) = base.scene.objects, base.scene.obstacles
    task = base.mission[0]
    for v in variants:
        scene = v.scenario.scene
        (obj,), (obs,) = scene.objects, scene.obstacles
        dz = scene.table.height - base.scene.table.height
        assert abs(dz) <= RANGES.table_height_m
        assert abs(math.degrees(obj.orientation_rad[2] - book.orientation_rad[2])) <= RANGES.yaw_deg + 1e-6
        assert RANGES.mass_kg[0] <= obj.mass <= RANGES.mass_kg[1]  # type: ignore[operator]
        assert RANGES.friction[0] <= obj.friction <= RANGES.friction[1]
        for new, old in zip(obj.size, book.size, strict=True):
            assert RANGES.scale[0] - 1e-6 <= new / old <= RANGES.scale[1] + 1e-6
        assert obj.size[0] >= obj.size[1]  # the book keeps its long axis
        for new_body, old_body in ((obj, book), (obs, stack)):
            assert np.all(
                np.abs(np.subtract(new_body.position[:2], old_body.position[:2])) <= RANGES.position_m
            )
        assert obs.position[2] == pytest.approx(stack.position[2] + dz, abs=1e-6)  # moves with the top
        shift = np.subtract(v.scenario.mission[0].to[:2], task.to[:2])
        assert np.all(np.abs(shift) <= RANGES.position_m + 1e-6)
    redraws = sum(v.redraws for v in variants)
    assert redraws > 0, "with +-10 cm shifts some draws must overlap the stack or leave the table"


def _geom_box_corners(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> np.ndarray:
    half = model.geom_size[geom]
    local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    return data.geom_xpos[geom] + local @ data.geom_xmat[geom].reshape(3, 3).T


def test_variants_are_physically_valid_scenes_in_mujoco(variants: list[Variant]) -> None:
    """The compiled worlds (MuJoCo's geometry, not the generator's coal check): the book lies on
    the table top, inside its edges, and clear of the stack."""
    for v in variants[:8]:
        world = build(v.scenario)
        model, data = world.model, world.data
        mujoco.mj_forward(model, data)
        book = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "book")
        stack = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "book_stack")
        fromto = np.zeros(6)
        gap = mujoco.mj_geomDistance(model, data, book, stack, 1.0, fromto)
        assert gap >= RANGES.clearance_m - 1e-6, f"variant {v.index}: book {gap:.4f} m from the stack"
        corners = _geom_box_corners(model, data, book)
        table = v.scenario.scene.table
        assert corners[:, 2].min() == pytest.approx(table.height, abs=1e-4)  # resting on the top
        inside = np.abs(corners[:, :2] - table.position) <= np.asarray(table.size[:2]) / 2
        assert inside.all(), f"variant {v.index}: the book reaches over the table's edge"


def test_written_variant_loads_back(tmp_path: Path, variants: list[Variant]) -> None:
    v = variants[2]
    loaded = write_variant(v, tmp_path / "variant-02.yaml")
    assert loaded == load(tmp_path / "variant-02.yaml")
    assert loaded.scene.objects[0].size == pytest.approx(v.scenario.scene.objects[0].size)
    assert loaded.scene.objects[0].position == pytest.approx(v.scenario.scene.objects[0].position, abs=1e-6)
    assert loaded.mission[0].to[:2] == pytest.approx(v.scenario.mission[0].to[:2])


def test_scene_problem_rejects_overlap_and_off_table(base: Scenario) -> None:
    import dataclasses

    book = base.scene.objects[0]
    stack = base.scene.obstacles[0]
    resting = {book.name, stack.name}
    assert scene_problem(base, resting, RANGES.clearance_m) is None
    into_stack = dataclasses.replace(book, position=(stack.position[0], 0.12, book.position[2]))
    scene = dataclasses.replace(base.scene, objects=(into_stack,))
    assert str(scene_problem(dataclasses.replace(base, scene=scene), resting, 0.01)).startswith("overlap")
    table = base.scene.table
    edge_y = table.position[1] + table.size[1] / 2 - 0.02  # centre on the top, an end over the edge
    off = dataclasses.replace(book, position=(book.position[0], edge_y, book.position[2]))
    scene = dataclasses.replace(base.scene, objects=(off,))
    assert str(scene_problem(dataclasses.replace(base, scene=scene), resting, 0.01)).startswith("off_table")


# --- regret -------------------------------------------------------------------------------------


def _record(trial: int, alternative: str, outcome: str, value: float | None) -> dict[str, Any]:
    predicted = None if value is None else {"value": value, "combined": 0.1}
    return {"trial": trial, "alternative": alternative, "outcome": outcome, "predicted": predicted}


def test_regret_on_a_hand_computed_table() -> None:
    """Trials 0-3 (+ one all-infeasible, one with a defect). Failures, by hand:

    trial  A  B      C   chosen (lowest value)
    0      1  0      0   A
    1      0  1      0   B
    2      1  inf.   1   C   (B infeasible: a failure, never chosen)
    3      0  0      1   C
    Even trials: A 2, B 1, C 1 failures -> best B (first of the tie); odd: A 0, B 1, C 1 -> A.
    Scored on the other half: t0 vs A (1, 1), t1 vs B (1, 1), t2 vs A (1, 1), t3 vs B (1, 0):
    one discordant trial where only the choice failed; regret 1/4. In-sample: chosen 4/4,
    best 2/4, naive regret 1/2.
    """
    rows = [
        ("A", "collision", 0.1), ("B", "success", 0.5), ("C", "success", 0.9),
        ("A", "success", 0.5), ("B", "drop", 0.1), ("C", "success", 0.9),
        ("A", "fall", 0.5), ("B", "infeasible", None), ("C", "collision", 0.2),
        ("A", "success", 0.5), ("B", "success", 0.9), ("C", "drop", 0.1),
    ]  # fmt: skip
    records = [_record(i // 3, a, o, v) for i, (a, o, v) in enumerate(rows)]
    records += [_record(4, a, "infeasible", None) for a in "ABC"]
    records += [
        _record(5, "A", "error", 0.1),
        _record(5, "B", "success", 0.2),
        _record(5, "C", "success", 0.3),
    ]
    table = trial_table(records, ["A", "B", "C"])
    assert table.dropped == {"incomplete": 0, "error": 1, "all_infeasible": 1}
    r = regret(table)
    assert r.best == {"even": "B", "odd": "A", "all": "A"}
    assert r.chosen == {"A": 1, "B": 1, "C": 2}
    assert (r.trials, r.choice_failures, r.best_failures, r.discordant) == (4, 4, 3, (1, 0))
    assert r.regret == pytest.approx(0.25) and r.naive_regret == pytest.approx(0.5)
    assert r.p_value == pytest.approx(1.0)
    assert r.ci95[0] < 0.25 < r.ci95[1]


def _expected_min_binomial(n: int, p: float, copies: int) -> float:
    """E[min of `copies` iid Binomial(n, p)] = sum_k P(X >= k)^copies."""
    tail = [sum(math.comb(n, i) * p**i * (1 - p) ** (n - i) for i in range(k, n + 1)) for k in range(n + 1)]
    return sum(t**copies for t in tail[1:])


def test_cross_fitting_removes_the_selection_bias_of_the_best_fixed_alternative() -> None:
    """Three alternatives with the same failure probability, predictions that know nothing:
    every policy fails as often, so the true regret is 0. The in-sample regret is biased up
    (against the choice) by p - E[min]/n (closed form); the cross-fitted one is unbiased."""
    n, p, reps = 20, 0.3, 3000
    rng = np.random.default_rng(11)
    naive, fitted = np.empty(reps), np.empty(reps)
    for i in range(reps):
        table = TrialTable(("A", "B", "C"), np.arange(n), rng.random((n, 3)) < p, rng.random((n, 3)))
        r = regret(table)
        assert r.regret is not None and r.naive_regret is not None
        naive[i], fitted[i] = r.naive_regret, r.regret
    bias = p - _expected_min_binomial(n, p, 3) / n
    assert bias > 0.05  # the bias the suite must not report as a loss of the ranking
    se_naive = naive.std(ddof=1) / math.sqrt(reps)
    se_fitted = fitted.std(ddof=1) / math.sqrt(reps)
    assert abs(naive.mean() - bias) < 4 * se_naive
    assert abs(fitted.mean()) < 4 * se_fitted
    assert abs(fitted.mean()) < 0.01


@pytest.mark.parametrize(("plus", "minus"), [(0, 0), (1, 0), (7, 1), (2, 9), (10, 2), (5, 5), (0, 6)])
def test_sign_test_is_the_exact_binomial(plus: int, minus: int) -> None:
    n = plus + minus
    tail = sum(math.comb(n, i) for i in range(min(plus, minus) + 1)) / 2**n
    assert sign_test(plus, minus) == pytest.approx(min(1.0, 2 * tail), rel=1e-12)


def test_newcombe_interval_covers_the_paired_difference() -> None:
    """Monte Carlo coverage of the 95% interval for correlated pairs (Newcombe 1998 reports
    near-nominal coverage for method 10)."""
    rng = np.random.default_rng(5)
    n, reps = 40, 2000
    cells = np.array([0.15, 0.15, 0.05, 0.65])  # both, first only, second only, neither
    truth = cells[1] - cells[2]
    hits = 0
    for _ in range(reps):
        both, first, second, neither = rng.multinomial(n, cells)
        low, high = newcombe_interval(both, first, second, neither)
        hits += low <= truth <= high
    assert 0.93 <= hits / reps <= 0.985


def test_rollouts_are_set_on_the_variant(base: Scenario) -> None:
    on = with_rollouts(base, 6).risk.rollouts
    assert on.count == 6 and on.min_count <= 6
    assert with_rollouts(base, 0).risk.rollouts.count == 0
    assert with_rollouts(base, 6).scene == base.scene


# --- end to end ---------------------------------------------------------------------------------


def test_bad_input_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    for argv, message in (
        (["--variants", "0", "--trials", "2"], "--variants must be at least 1"),
        (["--variants", "1", "--trials", "0"], "--trials must be at least 1"),
        (["--variants", "1", "--trials", "1", "--out", str(blocker / "suite")], "cannot write there"),
    ):
        assert main(["fidelity", "book_transfer", *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err


def test_fidelity_end_to_end_in_physics(tmp_path: Path) -> None:
    """One variant, then --resume extends the suite to two: the first is not run again."""
    out = tmp_path / "suite"
    argv = ["fidelity", "book_transfer", "--trials", "2", "--jobs", "1", "--out", str(out)]
    assert main([*argv, "--variants", "1"]) == 0
    first = (out / "variant-00" / "trials.jsonl").read_bytes()
    assert main([*argv, "--variants", "2"]) == 2  # the folder holds a suite: --resume or another --out
    assert main([*argv, "--variants", "2", "--resume", "--rollouts", "4"]) == 2  # not the suite's rollouts
    assert main([*argv, "--variants", "2", "--resume"]) == 0
    assert (out / "variant-00" / "trials.jsonl").read_bytes() == first
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] and summary["variants_run"] == 2 and summary["rollouts"] == 0
    assert set(summary["pooled"]) == {"collision", "fall", "drop", "tracking", "any"}
    assert {"mean", "significant_above_zero", "pooled", "variants_scored"} <= set(summary["regret"])
    assert summary["wall_s"] > 0
    executed = 0
    for row in summary["per_variant"]:
        assert [a["name"] for a in row["alternatives"]] == ["left", "right", "left_to_right"]
        assert load(out / row["yaml"]).name == row["name"]
        records = [
            json.loads(line) for line in (out / row["folder"] / "trials.jsonl").read_text().splitlines()
        ]
        assert len(records) == 2 * 3
        executed += sum(r["outcome"] not in ("infeasible", "error") for r in records)
        assert {"regret", "ci95", "p_value", "naive_regret"} <= set(row["regret"])
    assert summary["trials_executed"] == executed == summary["pooled"]["any"]["trials"]
    assert (out / "table.md").is_file() and (out / "reliability.png").is_file() == (executed > 0)


def test_each_variant_draws_its_truths_from_seeds_of_its_own(base: Scenario, variants: list[Variant]) -> None:
    """Variants that shared the base's trial seeds would share every truth error: 30 draws, not 30 K."""
    seeds = [v.scenario.trials.seed for v in variants]
    assert len(set(seeds)) == len(seeds)
    assert all(v.scenario.trials.scene_variation.is_zero() for v in variants)  # one estimate per variant


def test_the_pooled_auc_ceiling_scores_each_trial_by_its_groups_observed_rate() -> None:
    """Two (variant, alternative) groups: 2 events in 4 trials, and none in 4. Scored by the groups'
    rates (0.5, 0), the 2 events beat the 4 trials of the second group and tie the 2 quiet trials
    of their own: AUC (2 x 4 + 0.5 x 2 x 2) / (2 x 6) = 10 / 12."""
    from executive.validation.fidelity import pooled_statistics

    def record(variant: int, outcome: str) -> dict[str, object]:
        predicted = {"collision": 0.1, "fall": 0.0, "drop": 0.1, "combined": 0.2, "value": 0.3}
        return {"variant": variant, "alternative": "left", "outcome": outcome, "predicted": predicted}

    records = [record(0, o) for o in ("drop", "drop", "success", "success")]
    records += [record(1, "success") for _ in range(4)]
    pooled = pooled_statistics(records)
    assert pooled["drop"]["auc_ceiling"] == pytest.approx(10 / 12)
    assert pooled["drop"]["auc"] == pytest.approx(0.5)  # one prediction for all: no ranking at all
