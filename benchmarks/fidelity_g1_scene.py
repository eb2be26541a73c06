"""Write the G1 book scene for a fidelity suite: the shared Unitree G1 model, its own ranges.

The scene is tests/conftest.py's ``g1_scenario_yaml`` (the book transfer laid out for the G1's
Dex3 hands), with the G1's MJCF at ``../shared/robots/unitree_g1`` beside the checkout (the G1
is test data: the scene points at it, nothing is copied). It is written with the G1 family's
variation ranges beside it (``variation/g1_book_transfer.yaml``), which ``executive fidelity``
then finds::

    python -m benchmarks.fidelity_g1_scene DIR
    executive fidelity DIR/g1_book_transfer.yaml --variants 6 --trials 10 --jobs 2
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from benchmarks.g1_scenes import G1_MJCF, g1_book_yaml

ROOT = Path(__file__).resolve().parents[1]
RANGES = ROOT / "benchmarks" / "variation" / "g1_book_transfer.yaml"


def write(folder: Path) -> Path:
    """Write ``folder/g1_book_transfer.yaml`` and its ranges; the scene's path."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "g1_book_transfer.yaml"
    path.write_text(g1_book_yaml(G1_MJCF), encoding="utf-8")
    (folder / "variation").mkdir(exist_ok=True)
    shutil.copyfile(RANGES, folder / "variation" / RANGES.name)
    return path


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path, help="where to write the scene and its ranges")
    args = parser.parse_args()
    if not G1_MJCF.is_file():
        print(f"the shared Unitree G1 model is not at {G1_MJCF}", file=sys.stderr)
        return 2
    print(write(args.folder))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
