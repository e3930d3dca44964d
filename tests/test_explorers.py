"""The body explorer's callback logic (the ipywidgets layer only wires sliders to it)."""
import re

import matplotlib.pyplot as plt
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from graspkit.body import BodyModel
from graspkit.body.skeleton import JOINT_INDEX
from graspkit.paths import default_model_path
from graspkit.viz.explorers import BodyExplorer, BodyExplorerState, canonical_to_world, slider_bounds


@pytest.fixture(scope="module")
def explorer():
    return BodyExplorer(BodyModel.from_file(default_model_path()))


def test_height_slider_changes_stature(explorer):
    explorer.update("beta0", 0.0)
    h0 = explorer.stature()
    explorer.update("beta0", 2.0)
    h2 = explorer.stature()
    explorer.update("beta0", 0.0)
    assert h2 > h0 + 0.05


def test_elbow_slider_moves_the_wrist_by_the_forearm_rotation(explorer):
    _, j0 = explorer.mesh()
    _, j1 = explorer.update("left_elbow", np.pi / 2)
    explorer.update("left_elbow", 0.0)
    e, w = JOINT_INDEX["left_elbow"], JOINT_INDEX["left_wrist"]
    a, b = j0[w] - j0[e], j1[w] - j1[e]
    from scipy.spatial.transform import Rotation
    expected = Rotation.from_rotvec(np.pi / 2 * np.array([0.0, -1, 0])).apply(a)  # the slider's axis
    np.testing.assert_allclose(b, expected, atol=1e-5)
    assert b[2] > 0.9 * np.linalg.norm(b)                                          # the forearm now points forward
    np.testing.assert_allclose(j1[e], j0[e], atol=1e-6)


def test_unknown_slider_is_named():
    ex = BodyExplorer.__new__(BodyExplorer)
    ex.state = BodyExplorerState()
    with pytest.raises(ValueError, match="wiggle"):
        ex.state.set("wiggle", 1.0)


def test_a_non_finite_value_is_refused_and_leaves_the_state_alone(explorer):
    """NaN, inf or text for a slider: a ValueError naming the slider, and the explorer keeps working (a stored NaN
    used to break every later update, with an error naming body_pose)."""
    v0, _ = explorer.mesh()
    for bad in (float("nan"), float("inf"), "a lot"):
        with pytest.raises(ValueError, match="left_elbow: expected a (finite )?number"):
            explorer.update("left_elbow", bad)
        with pytest.raises(ValueError, match="beta1: expected a (finite )?number"):
            explorer.update("beta1", bad)
    v1, _ = explorer.update("beta0", 0.0)
    np.testing.assert_array_equal(v0, v1)


def test_the_widget_sliders_show_the_state_even_outside_their_range(explorer):
    pytest.importorskip("ipywidgets")
    explorer.update("beta0", 3.0)                            # beyond the ±2 range: ipywidgets would clamp to 2
    explorer.update("left_elbow", 0.5)
    try:
        with pytest.raises(ValueError, match="beta1: expected a number"):
            explorer.update("beta1", True)
        sliders = {s.description: s for s in explorer.widget(dpi=20).children[0].children}
        assert sliders["beta0"].value == 3.0 and sliders["beta0"].max == 3.0
        assert sliders["left_elbow"].value == 0.5 and (sliders["beta1"].min, sliders["beta1"].max) == (-2, 2)
    finally:
        explorer.update("beta0", 0.0)
        explorer.update("left_elbow", 0.0)


def test_slider_bounds_hold_the_value_on_either_side():
    assert slider_bounds(-3.0, -2.0, 2.0) == {"value": -3.0, "min": -3.0, "max": 2.0}
    assert slider_bounds(2.5, -2.0, 2.0) == {"value": 2.5, "min": -2.0, "max": 2.5}
    assert slider_bounds(0.5, -2.0, 2.0) == {"value": 0.5, "min": -2.0, "max": 2.0}


def test_canonical_to_world_is_the_rotation_about_x():
    """+90 deg about x (scipy), a proper rotation: canonical up (+y) becomes z, the body's front (+z) faces -y."""
    p = np.random.default_rng(0).normal(size=(20, 3))
    np.testing.assert_allclose(canonical_to_world(p), Rotation.from_euler("x", 90, degrees=True).apply(p), atol=1e-12)
    np.testing.assert_allclose(canonical_to_world(np.array([0.0, 1.0, 0.0])), [0.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(canonical_to_world(np.array([0.0, 0.0, 1.0])), [0.0, -1.0, 0.0], atol=1e-12)


def test_a_beta_past_the_models_is_an_unknown_slider():
    s = BodyExplorerState(np.zeros(10))
    with pytest.raises(ValueError, match="unknown slider 'beta10'"):
        s.set("beta10", 1.0)
    s.set("beta9", 1.0)
    assert s.betas[9] == 1.0


def test_body_explorer_stature_and_figure_are_the_canonical_y_extent(explorer):
    """The stature is the body's extent along canonical y (up), computed from the model's vertices at the explorer's
    betas and pose; the figure's title states it and its panels are centred on the body turned z up (scipy)."""
    ex, bm = explorer, explorer.bm
    ex.update("beta0", 1.5)
    with torch.no_grad():
        v = bm(betas=torch.as_tensor(ex.state.betas, dtype=bm.dtype)[None]).vertices[0].numpy().astype(float)
    h = v[:, 1].max() - v[:, 1].min()
    assert ex.stature() == pytest.approx(h, abs=1e-5)
    fig = ex.figure()
    assert float(re.search(r"stature ([0-9.]+) m", fig._suptitle.get_text()).group(1)) == pytest.approx(h, abs=0.006)
    w = Rotation.from_euler("x", 90, degrees=True).apply(v)
    for ax in fig.axes:
        assert np.mean(ax.get_zlim()) == pytest.approx((w[:, 2].max() + w[:, 2].min()) / 2, abs=1e-3)
    plt.close(fig)
    ex.update("beta0", 0.0)                                            # the module's explorer back at the mean shape


def test_a_value_past_the_sliders_bound_is_refused_and_the_state_kept(explorer):
    """beta3 = 1e39 (finite in float64, inf in the model's float32) was stored and then broke every later update
    with an error naming `betas`; an elbow turned 1e20 rad gave NaN vertices from then on, beta9 = -1e38 a 1e36 m
    body (independent checks). Values past a bound are refused by the slider's name, the state stays, and the next
    update gives the body before them."""
    v0, _ = explorer.mesh()
    for name, value, what in (("beta3", 1e39, "a shape coefficient"), ("beta9", -1e38, "a shape coefficient"),
                              ("left_elbow", 1e20, "an angle in radians"), ("neck", -7.0, "an angle in radians")):
        with pytest.raises(ValueError, match=f"^{name}: expected {what}.* within ±"):
            explorer.update(name, value)
        assert explorer.state.betas[[3, 9]].tolist() == [0.0, 0.0] and explorer.state.angles["left_elbow"] == 0.0
    v1, _ = explorer.update("beta0", 0.0)
    np.testing.assert_array_equal(v0, v1)
    explorer.update("beta0", 10.0)                                   # the bound itself: 10 stds, as documented
    with pytest.raises(ValueError, match="^beta0: expected a shape coefficient within ±10"):
        explorer.update("beta0", 10.5)
    assert explorer.state.betas[0] == 10.0
    explorer.update("beta0", 0.0)
    with pytest.raises(ValueError, match="^name: unknown slider 'beta01'"):      # was read as beta1
        explorer.update("beta01", 1.0)
    for bad in (12, -1, 2.5):
        with pytest.raises(ValueError, match="^betas_shown: expected"):
            explorer.widget(betas_shown=bad)
