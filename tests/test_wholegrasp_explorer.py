"""Lesson 05's latent-space walker: the callback decodes exactly what the model decodes, the numbers are right."""
import numpy as np
import pytest
import torch
from matplotlib.colors import to_rgba

from graspkit.body.markers import saga_markers
from graspkit.models.blocks import evaluating
from graspkit.models.wholegrasp import WholeGraspVAE
from graspkit.viz.saga import CONTACT_LEVEL, MARKER_IN_CONTACT, LatentWalk


@pytest.fixture(scope="module")
def walk():
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(1)
    pts = torch.randn(512, 3, generator=g) * 0.05
    return LatentWalk(WholeGraspVAE(), pts, torch.nn.functional.normalize(pts, dim=-1), 0.9, dims=3, seed=4)


def test_update_sets_one_latent_coordinate_and_decodes_it(walk):
    numbers = walk.update("z1", 1.5)
    assert walk.z[0, 1] == 1.5 and walk.names == ["z0", "z1", "z2", "seed"]
    assert walk.model.training                       # decoded in eval mode, the caller's model left as it was
    with torch.no_grad(), evaluating(walk.model):
        out = walk.model.decode(walk.z.clone(), walk.points[None], walk.normals[None], torch.tensor([[0.9]]))
    torch.testing.assert_close(walk.grasp["markers"], out["markers"][0])
    assert numbers["markers_in_contact"] == int((out["marker_contact"][0] > CONTACT_LEVEL).sum())
    assert numbers["points_in_contact"] == int((out["object_contact"][0] > CONTACT_LEVEL).sum())
    assert numbers["points_soft"] == pytest.approx(float(out["object_contact"][0].sum()), rel=1e-5)
    assert numbers["points_max"] == pytest.approx(float(out["object_contact"][0].max()), rel=1e-6)
    with pytest.raises(ValueError, match="z2: expected a finite number"):
        walk.update("z2", float("nan"))
    assert torch.isfinite(walk.z).all()
    m, p = walk.grasp["markers"].numpy(), walk.points.numpy()
    d = np.linalg.norm(m[121:143, None] - p[None], axis=-1).min()
    assert numbers["palm_to_object_cm"] == pytest.approx(100 * d, rel=1e-4)


def test_seed_draws_the_same_z_as_a_generator(walk):
    walk.update("seed", 7)
    torch.testing.assert_close(walk.z, torch.randn(1, 16, generator=torch.Generator().manual_seed(7)))
    a = walk.grasp["markers"].clone()
    walk.update("z0", 0.3)
    walk.update("seed", 7)
    torch.testing.assert_close(walk.grasp["markers"], a)


def test_bad_names_and_the_figure(walk):
    with pytest.raises(ValueError, match="name"):
        walk.update("z9", 1.0)
    with pytest.raises(ValueError, match="dims"):
        LatentWalk(walk.model, walk.points, walk.normals, 0.9, dims=17)
    fig = walk.figure(size=2.0)
    assert len(fig.axes) == 2
    assert walk.png()[:4] == b"\x89PNG"
    assert "markers" in LatentWalk.describe(walk.measure())


def test_palm_distance_is_the_right_palms(bm):
    """The latent explorer's palm_to_object_cm is the distance (cm) from the right palm's markers to the object: markers
    placed by hand, the left palm nearer than the right."""
    g = torch.Generator().manual_seed(0)
    pts = torch.nn.functional.normalize(torch.randn(256, 3, generator=g), dim=-1) * 0.05     # a 5 cm ball
    walk = LatentWalk(WholeGraspVAE(), pts, torch.nn.functional.normalize(pts, dim=-1), 0.9, dims=2, seed=0)
    names = saga_markers(bm).names
    right = np.array([n.startswith("RPALM_") for n in names])
    left = np.array([n.startswith("LPALM_") for n in names])
    assert right.sum() == 22 and left.sum() == 22
    m = torch.full((143, 3), 1.0)                                  # every marker 1.6 m from the ball's centre ...
    m[torch.as_tensor(right)] = torch.tensor([0.0, 0.0, 0.08])     # ... the right palm 3 cm above the ball
    m[torch.as_tensor(left)] = torch.tensor([0.0, 0.0, -0.06])     # ... the left palm 1 cm below it
    walk.grasp = {**walk.grasp, "markers": m}
    d = torch.cdist(torch.tensor([[0.0, 0.0, 0.08]]), pts).min()
    assert abs(walk.measure()["palm_to_object_cm"] - 100 * float(d)) < 1e-3
    assert abs(walk.measure()["palm_to_object_cm"] - 3.0) < 0.3


def test_latent_walk_dims_seed_and_z_norm(walk):
    """dims must be 1..latent (0 sliders is refused); the seed slider's value is kept; z_norm is the Euclidean norm
    of z (numpy)."""
    with pytest.raises(ValueError, match="dims"):
        LatentWalk(walk.model, walk.points, walk.normals, 0.9, dims=0)
    numbers = walk.update("seed", 11)
    assert walk.seed == 11
    assert numbers["z_norm"] == pytest.approx(float(np.linalg.norm(walk.z.numpy())), rel=1e-6)
    numbers = walk.update("z1", -2.5)
    assert numbers["z_norm"] == pytest.approx(float(np.linalg.norm(walk.z.numpy())), rel=1e-6)


def test_latent_walk_figure_draws_green_exactly_the_markers_above_the_level(walk):
    """The first panel draws in green the markers whose contact probability exceeds CONTACT_LEVEL and the others
    blue: counts from a hand-set contact vector."""
    cm = torch.linspace(0.0, 1.0, 143)
    walk.grasp = {**walk.grasp, "marker_contact": cm}
    fig = walk.figure(size=2.0)
    green = [c for c in fig.axes[0].collections
             if np.allclose(c.get_facecolor()[:, :3], to_rgba(MARKER_IN_CONTACT)[:3]) and len(c.get_offsets())]
    assert len(green) == 1
    assert len(green[0].get_offsets()) == int((cm > CONTACT_LEVEL).sum())
    walk.decode()


def test_a_bad_seed_or_height_is_named_and_changes_nothing(walk):
    """A fractional, boolean or negative seed was truncated or taken silently and a NaN height made every readout
    NaN (an independent check); each is now a ValueError naming the argument, and z stays as it was."""
    z = walk.z.clone()
    for value in (2.7, True, -4, None, "abc"):
        with pytest.raises(ValueError, match="^seed: expected a non-negative integer"):
            walk.update("seed", value)
    torch.testing.assert_close(walk.z, z, rtol=0, atol=0)
    with pytest.raises(ValueError, match="^seed:"):
        LatentWalk(walk.model, walk.points, walk.normals, 0.9, seed=2.5)
    with pytest.raises(ValueError, match="^height: expected a finite number"):
        LatentWalk(walk.model, walk.points, walk.normals, float("nan"))
    walk.update("seed", np.int64(5))                     # a numpy integer from a widget is a seed
    assert walk.seed == 5


def test_the_walk_takes_what_sample_takes_and_refuses_what_it_refuses(walk):
    """A height in millimetres, NaN points, a float `dims` and WholeGrasp-single were taken and gave nonsense or
    failed at the first update (KeyError 'object_contact'); numpy points failed with an AttributeError (an independent
    check). The walk now checks as WholeGraspVAE.sample does: numpy points decode the same as tensors."""
    from graspkit.models.wholegrasp import WholeGraspConfig

    p, n = walk.points, walk.normals
    bad_p = p.clone()
    bad_p[3, 0] = float("nan")
    for args, kwargs, message in (((p, n, 850.0), {}, "^height: 850, expected an object-centre height in metres"),
                                  ((p, n, -0.5), {}, "^height: -0.5"),
                                  ((bad_p, n, 0.9), {}, "^points:"),
                                  ((p[:, :2], n, 0.9), {}, "^points: expected shape"),
                                  ((p, n, 0.9), {"dims": 2.0}, "^dims: expected an integer >= 1")):
        with pytest.raises(ValueError, match=message):
            LatentWalk(walk.model, *args, **kwargs)
    torch.manual_seed(0)
    with pytest.raises(ValueError, match=r"^model: expected the multi-task WholeGrasp-VAE"):
        LatentWalk(WholeGraspVAE(WholeGraspConfig(multitask=False)), p, n, 0.9)
    with pytest.raises(TypeError, match=r"^model: expected a graspkit.models.wholegrasp.WholeGraspVAE"):
        LatentWalk(walk.model.state_dict(), p, n, 0.9)                   # the weights, not the model
    twin = LatentWalk(walk.model, p.numpy(), n.numpy(), 0.9, dims=3, seed=walk.seed)
    walk.update("seed", walk.seed)
    torch.testing.assert_close(twin.grasp["markers"], walk.grasp["markers"], rtol=0, atol=0)


def test_a_seed_or_latent_out_of_range_is_refused_and_changes_nothing(walk):
    """seed 2**64 failed in torch ('Overflow when unpacking long long') after being stored, so the slider showed a
    seed that did not match z; z0 = 1e30 gave |z| = inf (an independent check)."""
    walk.update("seed", 7)
    z = walk.z.clone()
    with pytest.raises(ValueError, match="^seed: expected a non-negative integer below 2\\^63"):
        walk.update("seed", 2**64)
    with pytest.raises(ValueError, match="^z0: expected a latent coordinate within"):
        walk.update("z0", 1e30)
    assert walk.seed == 7
    torch.testing.assert_close(walk.z, z, rtol=0, atol=0)


def test_the_object_panel_draws_green_only_the_hand_markers_in_contact(walk):
    """The second panel coloured every hand marker within 10 cm of the object in the 'in contact' green (40 green,
    28 in contact, an independent check): green there now means C_M above the level, as in the first panel."""
    cm = torch.zeros(143)
    cm[63:143:2] = 1.0                                       # every other hand marker in contact
    walk.grasp = {**walk.grasp, "markers": walk.points[:143].clone(), "marker_contact": cm}   # all near the object
    fig = walk.figure(size=2.0)
    def drawn(colour: str) -> int:
        return sum(len(c.get_offsets()) for c in fig.axes[1].collections
                   if len(c.get_offsets()) and np.allclose(c.get_facecolor()[:, :3], to_rgba(colour)[:3]))

    assert drawn(MARKER_IN_CONTACT) == 40 and drawn("#3b6ea8") == 40     # the other 40 near ones in the first's blue
    walk.decode()
