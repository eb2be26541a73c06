"""The Unitree G1 scenes the tests and the benchmarks share, pointing at the shared model.

The G1 (MuJoCo Menagerie's, with Dex3 hands) is test data at ``../shared/robots/unitree_g1``
beside the checkout: the scenes point at it, nothing is copied. Tests read them through
``tests/conftest.py``; benchmarks import them (``python -m benchmarks.NAME``)::

    from benchmarks.g1_scenes import G1_MJCF, g1_book_yaml, g1_floor_yaml
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["G1_DIR", "G1_MJCF", "g1_book_yaml", "g1_floor_yaml"]

# ../shared beside the checkout (CI clones main with shared/ beside it).
G1_DIR = Path(__file__).resolve().parents[2] / "shared" / "robots" / "unitree_g1"
G1_MJCF = G1_DIR / "g1_with_hands.xml"
_TRANSFER = "  - transfer: {object: book, to: [-0.55, -0.2]}\n"


def g1_book_yaml(mjcf: Path) -> str:
    """The book scene scaled to the G1 (1.3 m tall): a lower, nearer table.

    Laid out for the Dex3 hands, whose grasp is a palm-down pinch across the book's 9 cm width:
    a hand holding a book has its wrist about 10 cm to one side of it, so the stack stands
    behind the row of books (its front face 3 cm behind their far ends) and the books 22 cm
    either side of the midline (books at y = +-0.17 m beside a stack level with them left the
    wrist no room). The table's front edge is 1 cm under the books' near ends.
    """
    return f"""name: g1_book_transfer
description: The book transfer scene around the Unitree G1 with Dex3 hands.
robot: {{mjcf: {mjcf}, profile: unitree_g1}}
scene:
  table: {{position: [0.47, 0.0], size: [0.50, 1.0, 0.04], height: 0.66}}
  objects:
    - {{name: book, shape: box, size: [0.14, 0.09, 0.05], position: [0.30, 0.22], mass: 0.3}}
  obstacles:
    - {{name: book_stack, shape: box, size: [0.16, 0.12, 0.22], position: [0.48, 0.0]}}
uncertainty: {{object_position: 0.01, object_yaw: 3, obstacle_position: 0.01, com: 0.01}}
mission:
  - transfer: {{object: book, to: [0.30, -0.22]}}
"""


def g1_floor_yaml(
    mjcf: Path,
    com: float | None = None,
    *,
    name: str = "g1_floor",
    description: str = "The G1 on open floor, a table behind it.",
    mission: str = _TRANSFER,
) -> str:
    """The G1 on open floor, a table with a book behind it (out of its walks' way).

    Args:
        mjcf: the G1's MJCF.
        com: the scenario's ``uncertainty.com`` (m; None: the default), which sets the balance
            reserve a step plans with.
        name, description: the scenario's.
        mission: the ``mission`` block's items (YAML lines; default: a transfer of the book).
    """
    uncertainty = f"uncertainty: {{com: {com}}}\n" if com is not None else ""
    return f"""name: {name}
description: {description}
robot: {{mjcf: {mjcf}, profile: unitree_g1}}
scene:
  table: {{position: [-0.65, 0.0], size: [0.4, 0.8, 0.04], height: 0.66}}
  objects:
    - {{name: book, shape: box, size: [0.14, 0.09, 0.05], position: [-0.55, 0.2], mass: 0.3}}
  obstacles: []
{uncertainty}mission:
{mission}"""
