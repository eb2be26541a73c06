"""The scratch MjData pool (executive.world.scratch): fresh state, one borrower each, one model each."""

from __future__ import annotations

import threading

import mujoco
import numpy as np

from executive.world import scratch
from executive.world.scratch import scratch_data

_XML = """
<mujoco>
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint name="hinge" type="hinge" axis="0 1 0"/>
      <geom name="link" type="capsule" fromto="0 0 0 {length} 0 0" size="0.05" mass="{mass}"/>
    </body>
    <body name="target" mocap="true" pos="0.3 0.2 0.1"><geom type="sphere" size="0.02"/></body>
  </worldbody>
  <actuator><motor joint="hinge"/></actuator>
</mujoco>
"""


def _model(length: float = 0.5, mass: float = 1.0) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(_XML.format(length=length, mass=mass))


def _state(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS | mujoco.mjtState.mjSTATE_CTRL
    out = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, out, spec)
    return out


def test_a_returned_data_comes_back_in_a_fresh_datas_state() -> None:
    model = _model()
    with scratch_data(model) as data:
        first = data
        data.qpos[:] = 1.2
        data.qvel[:] = -3.0
        data.ctrl[:] = 0.7
        data.mocap_pos[0] = (5.0, 5.0, 5.0)
        mujoco.mj_forward(model, data)
    with scratch_data(model) as data:
        assert data is first  # the pool's data, not a new one
        np.testing.assert_array_equal(_state(model, data), _state(model, mujoco.MjData(model)))
        mujoco.mj_kinematics(model, data)
        fresh = mujoco.MjData(model)
        mujoco.mj_kinematics(model, fresh)
        np.testing.assert_array_equal(data.geom_xpos, fresh.geom_xpos)


def test_nested_and_concurrent_borrowers_get_different_datas() -> None:
    model = _model()
    with scratch_data(model) as outer, scratch_data(model) as inner:
        assert outer is not inner
    held, release = threading.Event(), threading.Event()
    seen: list[mujoco.MjData] = []

    def borrower() -> None:
        with scratch_data(model) as data:
            seen.append(data)
            held.set()
            release.wait()

    thread = threading.Thread(target=borrower)
    thread.start()
    assert held.wait(timeout=30.0)
    with scratch_data(model) as mine:
        assert mine is not seen[0]
    release.set()
    thread.join()


def test_another_model_never_gets_a_data_of_the_first() -> None:
    """A changed scene (the same XML with another link length, or only another mass) is another
    model: its borrower gets a data of its own model, whose kinematics follow the new link."""
    first, longer, heavier = _model(), _model(length=0.8), _model(mass=3.0)
    with scratch_data(first) as data:
        assert data.model is first
    for other, tip in ((longer, 0.8), (heavier, 0.5)):
        with scratch_data(other) as data:
            assert data.model is other
            mujoco.mj_kinematics(other, data)
            link = mujoco.mj_name2id(other, mujoco.mjtObj.mjOBJ_GEOM, "link")
            # the capsule's centre is half-way along the link
            np.testing.assert_allclose(data.geom_xpos[link], (tip / 2.0, 0.0, 1.0), atol=1e-12)
            np.testing.assert_allclose(other.body_subtreemass[1], 3.0 if other is heavier else 1.0)


def test_the_pools_of_at_most_the_last_models_are_kept() -> None:
    models = [_model(length=0.3 + 0.1 * i) for i in range(scratch.MODELS_KEPT + 2)]
    for m in models:
        with scratch_data(m):
            pass
    kept = [entry[0] for entry in scratch._POOLS.values()]
    assert len(kept) == scratch.MODELS_KEPT
    assert kept == models[-scratch.MODELS_KEPT :]
    with scratch_data(models[0]) as data:  # an evicted model gets a data of its own again
        assert data.model is models[0]
