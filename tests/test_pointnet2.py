"""PointNet++ in plain torch: sampling and grouping against brute-force numpy, invariances, the split first layer."""
import numpy as np
import pytest
import torch

from graspkit.models.pointnet2 import (PointNet2Encoder, SetAbstraction, ball_query, farthest_point_sample, gather,
                                       groupings_from_tensors, groupings_to_tensors, interpolate)
from graspkit.rotations import axis_angle_to_matrix


def _fps_numpy(p: np.ndarray, n: int) -> list[int]:
    """Textbook farthest-point sampling from index 0."""
    chosen = [0]
    d = np.full(len(p), np.inf)
    for _ in range(n - 1):
        d = np.minimum(d, ((p - p[chosen[-1]]) ** 2).sum(1))
        chosen.append(int(np.argmax(d)))
    return chosen


def test_fps_matches_numpy_and_picks_the_extremes_first():
    g = torch.Generator().manual_seed(0)
    x = torch.rand(3, 300, 3, generator=g, dtype=torch.float64)
    idx = farthest_point_sample(x, 40)
    for b in range(3):
        assert idx[b].tolist() == _fps_numpy(x[b].numpy(), 40)
    # points on a segment: after the start (one end) come the other end and then the middle
    line = torch.linspace(0, 1, 101, dtype=torch.float64)[:, None] * torch.tensor([[1.0, 0, 0]], dtype=torch.float64)
    assert farthest_point_sample(line[None], 3)[0].tolist() == [0, 100, 50]
    with pytest.raises(ValueError, match="n:"):
        farthest_point_sample(x, 301)
    with pytest.raises(ValueError, match="xyz"):
        farthest_point_sample(x[0], 3)


def test_ball_query_is_the_k_nearest_inside_the_radius():
    g = torch.Generator().manual_seed(1)
    x = torch.rand(2, 200, 3, generator=g, dtype=torch.float64)
    c = x[:, :10]
    idx = ball_query(x, c, radius=0.25, k=8)
    d = torch.cdist(c, x).numpy()
    for b in range(2):
        for s in range(10):
            inside = np.flatnonzero(d[b, s] <= 0.25)
            want = inside[np.argsort(d[b, s, inside], kind="stable")][:8]
            want = np.r_[want, np.full(8 - len(want), want[0])]            # short balls repeat the nearest
            assert sorted(idx[b, s].tolist()) == sorted(want.tolist())
            assert idx[b, s, 0] == s                                        # a centre is its own nearest
    lonely = ball_query(x, torch.full((2, 1, 3), 5.0, dtype=torch.float64), radius=0.1, k=4)
    assert (lonely == lonely[..., :1]).all()                                # nobody inside: one index repeated


def test_grouping_is_invariant_to_rigid_motion():
    g = torch.Generator().manual_seed(2)
    x = torch.rand(1, 512, 3, generator=g, dtype=torch.float64) * 0.1
    R = axis_angle_to_matrix(torch.tensor([0.3, -1.1, 0.7], dtype=torch.float64))
    y = x @ R.T + torch.tensor([0.5, -2.0, 1.0], dtype=torch.float64)
    enc = PointNet2Encoder(3)
    for a, b in zip(enc.group(x), enc.group(y)):
        if a is not None:
            assert torch.equal(a.centres, b.centres) and torch.equal(a.neighbours, b.neighbours)


def test_split_first_layer_equals_the_plain_set_abstraction():
    torch.manual_seed(0)
    sa = SetAbstraction(32, 0.3, 8, 4, [16, 24], norm=False).double()
    x = torch.rand(2, 256, 3, dtype=torch.float64)
    f = torch.randn(2, 256, 4, dtype=torch.float64)
    grp = sa.group(x)
    new_xyz, out = sa(x, f, grp)
    # textbook: shared MLP on [neighbour - centre, neighbour features], max over the neighbours
    local = gather(x, grp.neighbours) - new_xyz.unsqueeze(2)
    h = torch.cat([local, gather(f, grp.neighbours)], -1)
    for lin in sa.mlp.layers:
        h = torch.relu(lin(h))
    torch.testing.assert_close(out, h.max(2).values)
    assert out.shape == (2, 32, 24)


def test_encoder_is_permutation_invariant_and_passes_gradients():
    torch.manual_seed(0)
    enc = PointNet2Encoder(4).double().eval()
    x = torch.rand(2, 512, 3, dtype=torch.float64) * 0.1
    f = torch.randn(2, 512, 4, dtype=torch.float64, requires_grad=True)
    out = enc(x, f)
    assert [t.shape[1] for t in out.xyz] == [512, 256, 128, 1] and out.global_feature.shape == (2, 512)
    perm = torch.randperm(512)
    # a permutation changes FPS's start point; with the groupings carried along the output is identical
    grp = enc.group(x)
    inv = torch.argsort(perm)
    grp_p = [type(grp[0])(inv[grp[0].centres], inv[grp[0].neighbours])] + grp[1:]   # level 0 indexes the input
    torch.testing.assert_close(enc(x[:, perm], f[:, perm], grp_p).global_feature, enc(x, f, grp).global_feature)
    out.global_feature.sum().backward()
    assert f.grad.abs().sum() > 0
    tensors = groupings_to_tensors(grp)
    back = groupings_from_tensors(tensors, len(enc.sa))
    assert back[-1] is None and torch.equal(back[0].neighbours, grp[0].neighbours)
    with pytest.raises(ValueError, match="features"):
        enc(x, f[:, :100])


def test_interpolation_reproduces_coarse_features_at_their_points_and_constants():
    g = torch.Generator().manual_seed(3)
    coarse = torch.rand(1, 20, 3, generator=g, dtype=torch.float64)
    feat = torch.randn(1, 20, 5, generator=g, dtype=torch.float64)
    torch.testing.assert_close(interpolate(coarse, coarse, feat), feat, atol=1e-4, rtol=0)  # eps 1e-8 in 1/d^2
    fine = torch.rand(1, 100, 3, generator=g, dtype=torch.float64)
    const = torch.full((1, 20, 2), 3.5, dtype=torch.float64)
    torch.testing.assert_close(interpolate(fine, coarse, const), torch.full((1, 100, 2), 3.5, dtype=torch.float64))


def test_encoder_levels_are_sagas():
    enc = PointNet2Encoder(4)
    got = [(sa.npoint, sa.radius, sa.mlp.layers[-1].out_features) for sa in enc.sa]
    assert got == [(256, 0.2, 128), (128, 0.25, 256), (None, None, 512)]
    assert [sa.mlp.layers[0].out_features for sa in enc.sa] == [64, 128, 256]


def test_interpolation_weights_are_inverse_squared_distances_of_the_three_nearest():
    coarse = torch.tensor([[[1.0, 0, 0], [0, 2.0, 0], [0, 0, -3.0], [10.0, 10.0, 10.0]]], dtype=torch.float64)
    feat = torch.tensor([[[1.0], [2.0], [3.0], [100.0]]], dtype=torch.float64)
    fine = torch.zeros(1, 1, 3, dtype=torch.float64)               # distances 1, 2, 3 (and a far fourth point)
    w = torch.tensor([1.0, 1 / 4, 1 / 9], dtype=torch.float64)
    want = (w * torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64)).sum() / w.sum()
    torch.testing.assert_close(interpolate(fine, coarse, feat)[0, 0, 0], want, atol=1e-7, rtol=0)


def test_group_all_level_max_pools_the_shared_mlp_over_every_point():
    torch.manual_seed(0)
    sa = SetAbstraction(None, None, 8, 2, [16, 24], norm=False).double()
    x = torch.rand(2, 50, 3, dtype=torch.float64)
    f = torch.randn(2, 50, 2, dtype=torch.float64)
    centre, out = sa(x, f)
    h = torch.cat([x, f], -1)                                      # [xyz, features] of every point
    for lin in sa.mlp.layers:
        h = torch.relu(lin(h))
    torch.testing.assert_close(out[:, 0], h.max(1).values)
    assert centre.shape == (2, 1, 3) and float(centre.abs().max()) == 0.0


def test_ball_query_on_a_cloud_smaller_than_k_repeats_the_nearest():
    x = torch.tensor([[[0.0, 0, 0], [0.3, 0, 0], [0.1, 0, 0]]], dtype=torch.float64)   # N = 3 < k = 5
    c = torch.tensor([[[0.02, 0, 0], [0.29, 0, 0]]], dtype=torch.float64)
    idx = ball_query(x, c, radius=1.0, k=5)
    d = torch.cdist(c, x)[0].numpy()
    for s in range(2):
        order = np.argsort(d[s], kind="stable")                     # every point is inside the 1 m ball
        want = np.r_[order, np.full(5 - 3, order[0])]              # then the nearest repeated
        assert idx[0, s].tolist() == want.tolist()


def test_encoder_default_nsample_is_16():
    enc = PointNet2Encoder(4)
    assert [sa.nsample for sa in enc.sa[:2]] == [16, 16]
    g = enc.group(torch.rand(1, 300, 3, generator=torch.Generator().manual_seed(0)))
    assert g[0].neighbours.shape == (1, 256, 16) and g[1].neighbours.shape == (1, 128, 16)


def test_neighbours_of_a_float32_cloud_far_from_the_origin_are_those_of_the_same_cloud_at_it():
    """cdist's |a|^2 + |b|^2 - 2ab cancels far from the origin (1,000 m out, float32 neighbours came from 27 cm away):
    ball query and the 3-NN weights measure about the cloud, so a shift changes neither (truth: float64 at 0)."""
    from graspkit.models.pointnet2 import interpolation_weights
    g = torch.Generator().manual_seed(5)
    x = torch.randn(1, 2048, 3, generator=g, dtype=torch.float64) * 0.05
    c = x[:, :64]
    want_ball = ball_query(x, c, 0.02, 16)
    want_idx, want_w = interpolation_weights(x[:, :300], x[:, 300:400])
    for shift in (10.0, 1000.0):
        off = torch.tensor([shift, -shift, 0.5 * shift], dtype=torch.float64)
        xf = (x + off).float()                       # the float32 cloud far out; its rounding is the input's own
        ball = ball_query(xf, xf[:, :64], 0.02, 16)
        d_got = (xf[:, :64, None] - gather(xf, ball)).double().norm(dim=-1)
        assert d_got.max() <= 0.02 + 1e-4                                 # nobody from outside the ball
        same = [sorted(a.tolist()) == sorted(b.tolist()) for a, b in zip(ball[0], want_ball[0])]
        assert np.mean(same) > 0.9                                          # (float32 input rounding: 61 µm at 1 km)
        idx, w = interpolation_weights(xf[:, :300], xf[:, 300:400])
        assert (idx.sort(-1).values == want_idx.sort(-1).values).float().mean() > 0.97
        assert (w.double().sort(-1).values - want_w.sort(-1).values).abs().max() < (0.02 if shift > 100 else 1e-3)


def test_sampling_and_grouping_refuse_bad_arguments_by_name():
    x = torch.rand(1, 20, 3, generator=torch.Generator().manual_seed(0))
    for kw, name in ((dict(radius=float("nan"), k=4), "radius"), (dict(radius=float("inf"), k=4), "radius"),
                     (dict(radius=0.1, k=2.5), "k"), (dict(radius=0.1, k=True), "k"), (dict(radius=0.1, k=0), "k")):
        with pytest.raises(ValueError, match=f"^{name}:"):
            ball_query(x, x[:, :3], **kw)
    bad = x.clone()
    bad[0, 4, 1] = float("nan")
    with pytest.raises(ValueError, match="^xyz: contains NaN"):
        ball_query(bad, x[:, :3], 0.1, 4)
    with pytest.raises(ValueError, match="^xyz: contains NaN"):
        farthest_point_sample(bad, 3)
    for n in (2.0, 0, True):
        with pytest.raises(ValueError, match="^n:"):
            farthest_point_sample(x, n)
