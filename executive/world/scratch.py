"""Scratch ``MjData`` for a computation on a model: reused instead of made per call.

Making an ``MjData`` allocates and initialises its arena (megabytes for the bundled robot), which
costs far more than the kinematics most callers then run once; a risk model or the planner's
timing that needs a data for one query borrows one here instead::

    with scratch_data(model) as data:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        site = data.site_xpos[sid].copy()  # copy what outlives the block

A borrowed data is in the state ``mujoco.MjData(model)`` starts in (``mj_resetData``), is the
borrower's alone until its block ends (nested and concurrent borrowers get different ones) and
belongs to ``model`` only: the pools are kept per model object for the last
:data:`MODELS_KEPT` models borrowed for (a data holds its model, so a pool keeps its model alive
until it is dropped), each with at most :data:`IDLE_KEPT` idle datas.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Iterator
from contextlib import contextmanager

import mujoco

__all__ = ["IDLE_KEPT", "MODELS_KEPT", "scratch_data"]

MODELS_KEPT = 2  #: models whose pools are kept (the estimate's, and a truth world's beside it)
IDLE_KEPT = 3  #: idle datas kept per model (a nested borrower, another thread's)

_LOCK = threading.Lock()
# id(model) -> (model, idle datas); the model is kept so that its id is not reused meanwhile
_POOLS: OrderedDict[int, tuple[mujoco.MjModel, list[mujoco.MjData]]] = OrderedDict()


def _pool(model: mujoco.MjModel) -> list[mujoco.MjData]:
    """The idle datas of ``model`` (made empty if it has none), its pool made the most recent."""
    with _LOCK:
        entry = _POOLS.get(id(model))
        if entry is None or entry[0] is not model:
            entry = (model, [])
            _POOLS[id(model)] = entry
        _POOLS.move_to_end(id(model))
        while len(_POOLS) > MODELS_KEPT:
            _POOLS.popitem(last=False)
        return entry[1]


@contextmanager
def scratch_data(model: mujoco.MjModel) -> Iterator[mujoco.MjData]:
    """Borrow an ``MjData`` of ``model``, reset to its initial state, for the ``with`` block.

    Args:
        model: the model the data is for.

    Yields:
        A data no other borrower holds; do not keep it, or views into it, past the block.
    """
    pool = _pool(model)
    try:
        data = pool.pop()  # atomic: two threads never get the same data
    except IndexError:
        data = mujoco.MjData(model)
    else:
        mujoco.mj_resetData(model, data)
    try:
        yield data
    finally:
        if len(pool) < IDLE_KEPT:
            pool.append(data)
