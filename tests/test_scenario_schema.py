"""The scenario schema (``executive schema``) and the loader agree.

The shipped ``scenarios/scenario.schema.json`` is what the command prints and ``docs/scenarios.md``
is written from it; every bundled scenario names it and validates. On the malformed corpora
(tests/test_malformed_scenarios.py, tests/test_scenario_malformed.py) what the loader rejects
the schema rejects, except the cases listed below, each with the check a JSON Schema cannot
express (the loader-only checks of :data:`executive.scenario.json_schema.LOADER_ONLY`). Drawn
values at and past every declared range are accepted or rejected by both alike. (The converse,
that the schema accepts every scenario the loader accepts in any test, is checked for every test
by conftest.py.) A plug-in kind contributes its block's schema through ``TaskKind.schema()``.
"""

from __future__ import annotations

import copy
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import test_malformed_scenarios as corpus_validate  # tests/ is on sys.path (prepend import mode)
import test_scenario_malformed as corpus_load
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scenario_docs import walk
from schema_check import parse, problems, validator

from executive import scenario
from executive.errors import ScenarioError
from executive.scenario.json_schema import (
    LOADER_ONLY,
    SCHEMA_FILE,
    available_kinds,
    scenario_schema,
    schema_text,
)
from executive.scenario.keys import APPROVAL, RISK, TRIALS, UNCERTAINTY
from executive.scenario.schema_docs import schema_markdown
from executive.schema.declarations import Block, Integer, Number
from executive.schema.scene_keys import OBJECT, OBSTACLE
from executive.tasks import registry

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "scenarios" / SCHEMA_FILE
BUNDLED = sorted((ROOT / "scenarios").glob("*.yaml"))
SOURCE = (ROOT / "scenarios" / "book_transfer.yaml").read_text()

DUPLICATE, WHOLE, FINITE, GEOMETRY, REACH, NAMES, HELD, ACROSS, FILES, MODULES = (
    name for name, _ in LOADER_ONLY
)

#: The malformed cases only the loader rejects, by corpus and case id, with the check it takes.
SCHEMA_CANNOT: dict[str, dict[str, str]] = {
    "test_malformed_scenarios": {
        **{
            f"dup-{key}": DUPLICATE
            for key in ("threshold", "name", "table-height", "mass", "com", "com-margin", "body-part")
        },
        "dup-object": DUPLICATE,
        "dup-block": DUPLICATE,
        "nan-mass": FINITE,
        "nan-yaw-sigma": FINITE,
        "nan-to-yaw": FINITE,
        "nan-clearance": FINITE,
        "threshold-99": ACROSS,
        "threshold-at-max": ACROSS,
        "threshold-probability": ACROSS,
        "threshold-weighted-sum": ACROSS,
        "threshold-severities": ACROSS,
        "threshold-zero-weights": ACROSS,
        "threshold-above-obstacle-severity": ACROSS,
        "grasp-weights-zero": ACROSS,
        "object-overlaps-obstacle": GEOMETRY,
        "object-inside-obstacle": GEOMETRY,
        "object-turned-into-obstacle": GEOMETRY,
        "obstacle-onto-object": GEOMETRY,
        "objects-overlap": GEOMETRY,
        "object-floats": GEOMETRY,
        "object-hovers": GEOMETRY,
        "object-in-table": GEOMETRY,
        "object-on-floor": GEOMETRY,
        "object-off-table-z": GEOMETRY,
        "target-in-obstacle": GEOMETRY,
        "target-touching-deep": GEOMETRY,
        "target-on-object": GEOMETRY,
        "target-off-table-z": GEOMETRY,
        "target-on-floor": GEOMETRY,
        "target-floats": GEOMETRY,
        "target-off-table-xy": GEOMETRY,
        "object-far": REACH,
        "target-far": REACH,
        "target-far-side": REACH,
        "table-far": REACH,
        "table-far-to-the-side": REACH,
        **{f"body-part-{name}": NAMES for name in ("hnad", "haed", "foreamr", "Head", "tosro", "left_hand")},
        **{f"mjcf-{what}": FILES for what in ("is-yaml", "is-text", "is-empty", "other-xml", "missing")},
        "mjcf-symlink-loop": FILES,
        **{
            f"profile-{what}": FILES
            for what in ("symlink-loop", "nul-byte", "nul-name", "no-such-user", "a-folder", "missing")
        },
        "place-unpicked": HELD,
        "place-placed": HELD,
        "place-after-transfer": HELD,
        "pick-held": HELD,
        "transfer-held": HELD,
        "push-held": HELD,
        "press-held": HELD,
        **{
            f"kind-{path}": MODULES
            for path in ("this-Zen", "os-system", "subprocess-Popen", "os.path-join", "tripwire_never-Kind")
        },
    },
    "test_scenario_malformed": {
        "grasp-scale-above-max": ACROSS,
        "reversed-perception-scale": ACROSS,
        "yaw-symmetry-of-oblong-box": ACROSS,
        "nan-height": FINITE,
        "missing-mjcf-file": FILES,
        "object-inside-table": GEOMETRY,
        "obstacle-below-floor": GEOMETRY,
        "target-off-the-table": GEOMETRY,
        "duplicate-name": NAMES,
        "unknown-task-object": NAMES,
        "task-object-is-an-obstacle": NAMES,
    },
}


def _python(*code: str) -> subprocess.CompletedProcess[str]:
    """Run ``python -c`` in the checkout (its package first on sys.path)."""
    return subprocess.run(
        [sys.executable, "-c", "\n".join(code)], cwd=ROOT, capture_output=True, text=True, timeout=120
    )


def test_the_shipped_schema_is_what_the_command_prints_without_importing_jsonschema() -> None:
    done = _python(
        "import sys",
        "from executive.cli.main import main",
        "code = main(['schema'])",
        "sys.stderr.write(f'jsonschema imported: {\"jsonschema\" in sys.modules}')",
        "sys.exit(code)",
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout == SHIPPED.read_text(), (
        "scenarios/scenario.schema.json is out of date: executive schema > scenarios/scenario.schema.json"
    )
    assert done.stderr.endswith("jsonschema imported: False"), done.stderr
    assert schema_text(scenario_schema()) == done.stdout


def test_docs_scenarios_md_is_written_from_the_schema() -> None:
    expected = schema_markdown(scenario_schema())
    assert (ROOT / "docs" / "scenarios.md").read_text() == expected, (
        "docs/scenarios.md is out of date: executive schema --markdown > docs/scenarios.md"
    )
    for key in ("`min_com_margin`", "`perception_scale`", "`mission[].press`", "`yaw_symmetry`"):
        assert key in expected


def test_the_schema_is_a_2020_12_schema_and_every_key_is_described() -> None:
    schema = scenario_schema()
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    validator()  # checks the schema against the 2020-12 meta-schema

    def undescribed(node: Any, path: str) -> list[str]:
        missing = []
        for key, sub in node.get("properties", {}).items():
            if not sub.get("description") and not sub.get("const"):
                missing.append(f"{path}.{key}")
            missing += undescribed(sub, f"{path}.{key}")
        for option in node.get("oneOf", []) + [c["then"] for c in node.get("allOf", [])]:
            if "type" in option:  # a value's schema, not a constraint on keys described above
                missing += undescribed(option, path)
        if isinstance(node.get("items"), dict):
            missing += undescribed(node["items"], f"{path}[]")
        return missing

    assert undescribed(schema, "") == []
    guard = schema["properties"]["risk"]["properties"]["guard"]["properties"]["min_com_margin"]
    assert (guard["x-unit"], guard["x-range"], guard["default"]) == ("m", "[0, 0.3]", 0.02)
    assert guard["minimum"] == 0 and guard["maximum"] == 0.3


@pytest.mark.parametrize("path", BUNDLED, ids=[p.stem for p in BUNDLED])
def test_every_bundled_scenario_names_the_schema_and_validates(path: Path) -> None:
    first = path.read_text().splitlines()[0]
    assert first == f"# yaml-language-server: $schema={SCHEMA_FILE}"
    assert (path.parent / SCHEMA_FILE).is_file()
    assert problems(parse(path.read_text())) == []


def _document(module: Any, case: Any, tmp_path: Path) -> str:
    """The case's YAML text, made as its corpus makes it (from this checkout's book_transfer)."""
    takes_tmp = module is corpus_validate
    if case.on_text:
        return case.mutate(SOURCE, tmp_path) if takes_tmp else case.mutate(SOURCE)
    data = copy.deepcopy(yaml.safe_load(SOURCE))
    data = case.mutate(data, tmp_path) if takes_tmp else case.mutate(data)
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True)


def _schema_rejects(text: str) -> bool:
    """What an editor does: parse the YAML (a document it cannot parse is rejected), then validate."""
    try:
        document = parse(text)
    except yaml.YAMLError:
        return True
    return not validator().is_valid(document)


@pytest.mark.parametrize("module", [corpus_validate, corpus_load], ids=lambda m: m.__name__)
def test_the_loader_and_the_schema_reject_the_same_malformed_scenarios(
    module: Any, tmp_path_factory: pytest.TempPathFactory
) -> None:
    cannot = SCHEMA_CANNOT[module.__name__]
    assert set(cannot.values()) <= {name for name, _ in LOADER_ONLY}
    assert set(cannot) <= {case.id for case in module.CASES}, "a listed case left its corpus"
    accepted_by_loader, disagree = [], {}
    for case in module.CASES:
        tmp = tmp_path_factory.mktemp("case")
        path = tmp / "case.yaml"
        path.write_text(_document(module, case, tmp))
        try:
            scenario.load(path)
            accepted_by_loader.append(case.id)
        except ScenarioError:
            pass
        if not _schema_rejects(path.read_text()):
            disagree[case.id] = cannot.get(case.id, "(not listed: the schema should reject it)")
    assert accepted_by_loader == []
    assert disagree == cannot, "cases the schema accepts (expected: the listed ones)"


def test_what_people_write_and_mean_passes_both(tmp_path: Path) -> None:
    for label, mutate in corpus_validate.ACCEPTED:
        text = mutate(SOURCE, tmp_path)
        path = tmp_path / "ok.yaml"
        path.write_text(text)
        scenario.load(path)
        assert problems(parse(text)) == [], label


def _number_keys() -> list[tuple[str, Number | Integer]]:
    """Key paths in book_transfer of every declared number whose range involves no other key
    (the table's keys move the scene about it: the geometry's checks)."""
    blocks: list[tuple[str, Block]] = [
        ("uncertainty", UNCERTAINTY),
        ("approval", APPROVAL),
        ("trials", TRIALS),
        ("risk", RISK),
        ("scene.objects[0]", OBJECT),
        ("scene.obstacles[0]", OBSTACLE),
    ]
    across = {
        "risk.threshold",
        "risk.rollouts.min_count",
        *(f"risk.grasp.{key}" for key in ("position_scale", "position_max", "angle_scale", "angle_max")),
        "scene.objects[0].yaw_symmetry",
    }
    found = []
    while blocks:
        path, block = blocks.pop()
        for key, spec in block.keys.items():
            where = f"{path}.{key}"
            if isinstance(spec, Block):
                blocks.append((where, spec))
            elif isinstance(spec, Number | Integer) and where not in across:
                found.append((where, spec))
    return sorted(found, key=lambda pair: pair[0])


NUMBER_KEYS = _number_keys()


@st.composite
def _past_a_range(draw: st.DrawFn) -> tuple[str, Number | Integer, object]:
    """A declared number's key path, its declaration and a value at, inside, just past or far past
    its range, or of another type."""
    path, spec = draw(st.sampled_from(NUMBER_KEYS))
    ends = [v for v in (spec.low, spec.high) if v is not None]
    near = [end + step for end in ends for step in (-1e-9, 0.0, 1e-9, -1.0, 1.0)]
    value = draw(
        st.one_of(
            st.sampled_from([*near, *ends, 0, -1, 1e308, math.inf, -math.inf, True, "1", None]),
            st.floats(allow_nan=False),
            st.integers(-(2**40), 2**40),
        )
    )
    return path, spec, value


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(change=_past_a_range())
def test_every_declared_range_is_read_alike_by_both(change: tuple[str, Number | Integer, object]) -> None:
    path, spec, value = change
    data = yaml.safe_load(SOURCE)
    node, key = walk(data, path)
    node[key] = value
    try:
        scenario.from_dict(copy.deepcopy(data), source="drawn.yaml")
        loader_rejects = False
    except ScenarioError:
        loader_rejects = True
    if isinstance(spec, Integer) and isinstance(value, float) and value.is_integer():
        assert loader_rejects, f"{path} = {value!r}"  # the schema counts it an integer: WHOLE
    else:
        assert loader_rejects == (problems(data) != []), f"{path} = {value!r}"


def _wave_kind(monkeypatch: pytest.MonkeyPatch) -> type:
    monkeypatch.syspath_prepend(str(ROOT / "examples" / "plugin_kind"))
    monkeypatch.setattr(registry, "_registered", dict(registry._registered))
    from wave_kind import WaveKind

    return WaveKind


def test_a_plug_in_kind_brings_its_own_block(monkeypatch: pytest.MonkeyPatch) -> None:
    """The wave kind declares no keys: the default schema names it, describes it and checks its
    alternatives; its other keys are its own. A kind that declares keys gets them checked."""
    wave = registry.register(_wave_kind(monkeypatch))
    kinds, failed = available_kinds()
    assert failed == [] and "wave" in [k.name for k in kinds]
    schema = scenario_schema(kinds)
    block = schema["properties"]["mission"]["items"]["oneOf"][0]["properties"]["wave"]
    assert block["description"].startswith("The ``wave`` kind")
    data = yaml.safe_load(SOURCE)
    data["mission"] = [{"wave": {"at": [0.45, 0.1], "alternatives": ["left"]}}]
    assert problems(data, kinds) == []
    assert problems(data) != []  # the built-in kinds' schema does not know it
    data["mission"] = [{"wave": {"at": [0.45, 0.1], "alternatives": ["both"]}}]
    assert any("both" in p for p in problems(data, kinds))

    class Declared(type(wave)):  # type: ignore[misc]
        name = "declared_wave"
        keys = Block("a wave whose keys are declared", {"height": Number("how high", "m", 0.0, 1.0)})

    declared = Declared()
    data["mission"] = [{"declared_wave": {"height": 2.0}}]
    assert any("height" in p for p in problems(data, [*kinds, declared]))
    data["mission"] = [{"kind": "declared_wave", "height": 0.5}]
    assert problems(data, [*kinds, declared]) == []


def test_executive_schema_kind_adds_a_plug_in(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from executive.cli.main import main

    _wave_kind(monkeypatch)
    assert main(["schema", "--kind", "wave_kind:WaveKind", "--markdown"]) == 0
    out = capsys.readouterr().out
    assert "## `mission[].wave`" in out and "Other keys are the kind's own" in out
    assert main(["schema", "--kind", "no_such_module_x:Kind"]) == 2
    assert "cannot import 'no_such_module_x'" in capsys.readouterr().err


def test_a_scenario_the_schema_refuses_is_reported_by_the_watch(monkeypatch: pytest.MonkeyPatch) -> None:
    """The check conftest.py makes of every loaded scenario can fail (here, a check that refuses all)."""
    from schema_check import watch_loader

    refused = watch_loader(monkeypatch, check=lambda document, kinds: ["risk: made up"])
    scenario.from_dict(yaml.safe_load(SOURCE))
    assert refused == ["<dict>: risk: made up"]
    with pytest.raises(ScenarioError):
        scenario.from_dict({"name": "x"})
    assert refused == ["<dict>: risk: made up"]  # a rejected document is the loader's business only
