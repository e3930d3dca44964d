"""PointNet++ (Qi et al., NeurIPS 2017) in plain torch: farthest-point sampling, ball query, set abstraction,
feature propagation. No CUDA extension; every step is a tensor operation that runs on CPU or GPU.

SAGA App. A.2 encodes the object (2,048 surface points, xyz + normal) with
    SA(256, 0.2, [64, 128]) -> SA(128, 0.25, [128, 256]) -> SA([256, 512])
where SA(npoint, radius, mlp) is a set-abstraction level: pick `npoint` centres by farthest-point sampling, gather
up to `nsample` neighbours within `radius` of each (ball query), run a shared MLP on (neighbour - centre, neighbour
features) and max-pool over the neighbours; the last level groups all points into one global feature. The paper does
not give `nsample`; `PointNet2Encoder` defaults to 16 and WholeGrasp and GrabNet-SMPLX use 8
(`WholeGraspConfig.nsample`; PointNet++ uses 32-64 on 10k-point scenes; few neighbours keep training on two CPU cores
within budget). Per-point outputs (SAGA's object contact map) come from feature propagation: inverse-distance
interpolation from the 3 nearest coarser points, concatenated with the finer level's features, then a shared MLP.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from graspkit.checks import check_int, check_positive
from graspkit.objects.distance import centred_cdist


def _check_points(xyz: Tensor, name: str = "xyz") -> None:
    """Raise a ValueError naming `name` unless xyz is (B, N, 3) and finite."""
    if not isinstance(xyz, Tensor) or xyz.dim() != 3 or xyz.shape[-1] != 3:
        shape = tuple(xyz.shape) if isinstance(xyz, Tensor) else type(xyz).__name__
        raise ValueError(f"{name}: expected a tensor of shape (B, N, 3), got {shape}")
    if not torch.isfinite(xyz).all():
        raise ValueError(f"{name}: contains NaN or Inf")


def farthest_point_sample(xyz: Tensor, n: int, generator: torch.Generator | None = None) -> Tensor:
    """Indices (B, n) of points greedily farthest from those already chosen, xyz (B, N, 3).

    Starts at point 0 (as the reference CUDA kernel) unless a generator picks a random start per cloud.
    """
    _check_points(xyz)
    B, N, _ = xyz.shape
    if check_int(n, "n", least=1) > N:
        raise ValueError(f"n: expected at most {N} samples (xyz has {N} points), got {n}")
    idx = torch.empty(B, n, dtype=torch.long, device=xyz.device)
    if generator is None:
        far = torch.zeros(B, dtype=torch.long, device=xyz.device)
    else:
        far = torch.randint(N, (B,), generator=generator, device=xyz.device)
    dist = torch.full((B, N), float("inf"), dtype=xyz.dtype, device=xyz.device)
    rows = torch.arange(B, device=xyz.device)
    with torch.no_grad():
        for i in range(n):
            idx[:, i] = far
            d = (xyz - xyz[rows, far].unsqueeze(1)).pow(2).sum(-1)
            dist = torch.minimum(dist, d)
            far = dist.argmax(-1)
    return idx


def ball_query(xyz: Tensor, centres: Tensor, radius: float, k: int) -> Tensor:
    """Indices (B, S, k) of the k nearest points within `radius` of each centre (B, S, 3), nearest first.

    Centres with fewer than k neighbours in the ball repeat their nearest one. The reference kernel takes the
    first k in index order instead; on objects smaller than the radius (SAGA's 0.2 m ball around a 10 cm mug)
    that is the same k points for every centre, so graspkit keeps the k nearest (a documented deviation).
    """
    _check_points(xyz)
    _check_points(centres, "centres")
    check_positive(radius, "radius")
    check_int(k, "k", least=1)
    N = xyz.shape[1]
    with torch.no_grad():
        d2 = centred_cdist(centres, xyz).pow(2)                               # (B, S, N)
        kk = min(k, N)
        d, idx = d2.topk(kk, dim=-1, largest=False, sorted=True)
        idx = torch.where(d <= radius * radius, idx, idx[..., :1].expand_as(idx))
        if kk < k:
            idx = torch.cat([idx, idx[..., :1].expand(*idx.shape[:-1], k - kk)], -1)
    return idx


def gather(x: Tensor, idx: Tensor) -> Tensor:
    """Rows of x (B, N, C) at idx (B, ...) -> (B, ..., C)."""
    B = x.shape[0]
    flat = idx.reshape(B, -1)
    out = torch.gather(x, 1, flat.unsqueeze(-1).expand(-1, -1, x.shape[-1]))
    return out.reshape(*idx.shape, x.shape[-1])


class SharedMLP(nn.Module):
    """A point-wise MLP on the last dimension, (..., C_in) -> (..., C_out): Linear (+ BatchNorm) + ReLU per layer."""

    def __init__(self, sizes: list[int], norm: bool = True) -> None:
        super().__init__()
        self.layers = nn.ModuleList(nn.Linear(a, b) for a, b in zip(sizes[:-1], sizes[1:]))
        self.norms = nn.ModuleList(nn.BatchNorm1d(b) if norm else nn.Identity() for b in sizes[1:])

    def forward(self, x: Tensor) -> Tensor:
        """(..., C_in) -> (..., C_out)."""
        return self.rest(self.layers[0](x))

    def rest(self, h: Tensor) -> Tensor:
        """Everything after the first Linear: its output (..., C_1) -> (..., C_out)."""
        shape = h.shape[:-1]
        h = h.reshape(-1, h.shape[-1])
        for i, (lin, bn) in enumerate(zip(self.layers, self.norms)):
            h = torch.relu(bn(h if i == 0 else lin(h)))
        return h.reshape(*shape, h.shape[-1])


@dataclass
class Grouping:
    """Where one set-abstraction level looks: centre indices (B, S) into the level's input and neighbours (B, S, k)."""

    centres: Tensor
    neighbours: Tensor


def groupings_to_tensors(groupings: list[Grouping | None]) -> dict[str, Tensor]:
    """Groupings as plain tensors (for datasets / DataLoader batches): {'g{i}_centres', 'g{i}_neighbours'}."""
    out = {}
    for i, g in enumerate(groupings):
        if g is not None:
            out[f"g{i}_centres"], out[f"g{i}_neighbours"] = g.centres, g.neighbours
    return out


def groupings_from_tensors(batch: dict[str, Tensor], levels: int) -> list[Grouping | None] | None:
    """Inverse of groupings_to_tensors for `levels` levels (the group-all level is None); None if absent."""
    if "g0_centres" not in batch:
        return None
    return [Grouping(batch[f"g{i}_centres"], batch[f"g{i}_neighbours"]) if f"g{i}_centres" in batch else None
            for i in range(levels)]


class SetAbstraction(nn.Module):
    """SA(npoint, radius, mlp): (xyz (B,N,3), features (B,N,C) | None) -> (centres (B,S,3), features (B,S,mlp[-1])).

    With npoint=None the level groups all points around the origin into one feature (S = 1).
    """

    def __init__(self, npoint: int | None, radius: float | None, nsample: int, in_channels: int,
                 mlp: list[int], norm: bool = True) -> None:
        super().__init__()
        self.npoint, self.radius, self.nsample = npoint, radius, nsample
        self.mlp = SharedMLP([in_channels + 3] + list(mlp), norm)
        self.out_channels = mlp[-1]

    def group(self, xyz: Tensor) -> Grouping | None:
        """The level's centres and neighbourhoods for xyz (B, N, 3) (no gradient; reusable across branches)."""
        if self.npoint is None:
            return None
        centres = farthest_point_sample(xyz, self.npoint)
        return Grouping(centres, ball_query(xyz, gather(xyz, centres), self.radius, self.nsample))

    def forward(self, xyz: Tensor, features: Tensor | None, grouping: Grouping | None = None
                ) -> tuple[Tensor, Tensor]:
        """(B,N,3), (B,N,C)|None -> centres (B,S,3), pooled features (B,S,C_out)."""
        if self.npoint is None:
            h = xyz if features is None else torch.cat([xyz, features], -1)
            new_xyz = xyz.new_zeros(xyz.shape[0], 1, 3)
            return new_xyz, self.mlp(h).max(dim=1, keepdim=True).values
        g = grouping if grouping is not None else self.group(xyz)
        new_xyz = gather(xyz, g.centres)                                       # (B, S, 3)
        # the first Linear on [neighbour - centre, neighbour features] split into a per-point and a per-centre
        # term (W [p - c, f] + b = (W_p p + W_f f + b) - W_p c): the same function, computed on N + S rows
        # instead of S * k
        lin = self.mlp.layers[0]
        per_point = torch.nn.functional.linear(xyz, lin.weight[:, :3], lin.bias)
        if features is not None:
            per_point = per_point + features @ lin.weight[:, 3:].T
        per_centre = new_xyz @ lin.weight[:, :3].T
        first = gather(per_point, g.neighbours) - per_centre.unsqueeze(2)    # (B, S, k, C_1)
        return new_xyz, self.mlp.rest(first).max(dim=2).values


class FeaturePropagation(nn.Module):
    """Interpolate coarse features (B,S,C2) at xyz2 onto xyz1 (B,N,3) by inverse distance over the 3 nearest,
    concatenate the fine features (B,N,C1), shared MLP -> (B,N,mlp[-1])."""

    def __init__(self, in_channels: int, mlp: list[int], norm: bool = True) -> None:
        super().__init__()
        self.mlp = SharedMLP([in_channels] + list(mlp), norm)

    def forward(self, xyz1: Tensor, xyz2: Tensor, feat1: Tensor | None, feat2: Tensor,
                weights: tuple[Tensor, Tensor] | None = None) -> Tensor:
        """Fine (B,N,3), coarse (B,S,3), fine features (B,N,C1)|None, coarse features (B,S,C2) -> (B,N,C_out);
        `weights` = interpolation_weights(xyz1, xyz2) when precomputed."""
        interp = interpolate(xyz1, xyz2, feat2, weights=weights)
        h = interp if feat1 is None else torch.cat([feat1, interp], -1)
        return self.mlp(h)


def interpolation_weights(xyz1: Tensor, xyz2: Tensor, k: int = 3) -> tuple[Tensor, Tensor]:
    """The k nearest coarse points of every fine point and their normalised inverse-squared-distance weights:
    (B,N,3), (B,S,3) -> indices (B,N,k), weights (B,N,k). Invariant to rigid motions of the cloud (to rounding:
    the distances are taken about the coarse cloud's mean)."""
    with torch.no_grad():
        d, idx = centred_cdist(xyz1, xyz2).topk(min(k, xyz2.shape[1]), dim=-1, largest=False)
        w = 1.0 / (d.pow(2) + 1e-8)
    return idx, w / w.sum(-1, keepdim=True)


def interpolate(xyz1: Tensor, xyz2: Tensor, feat2: Tensor, k: int = 3,
                weights: tuple[Tensor, Tensor] | None = None) -> Tensor:
    """Inverse-squared-distance average of the k nearest coarse features: (B,N,3), (B,S,3), (B,S,C) -> (B,N,C)."""
    if xyz2.shape[1] == 1:
        return feat2.expand(-1, xyz1.shape[1], -1)
    idx, w = weights if weights is not None else interpolation_weights(xyz1, xyz2, k)
    return (gather(feat2, idx) * w.unsqueeze(-1)).sum(2)


@dataclass
class PointNet2Output:
    """The levels of a PointNet++ encoder: xyz and features per level (input level first); the last is global."""

    xyz: list[Tensor]
    features: list[Tensor | None]

    @property
    def global_feature(self) -> Tensor:
        """(B, C) feature of the whole cloud."""
        return self.features[-1][:, 0]


class PointNet2Encoder(nn.Module):
    """SAGA's object encoder (App. A.2): SA(256, 0.2, [64,128]) -> SA(128, 0.25, [128,256]) -> SA([256,512]).

    Input: xyz (B,N,3) and per-point features (B,N,C) (normals, and in SAGA's encoder also the object contacts).
    """

    def __init__(self, in_channels: int, nsample: int = 16,
                 levels: tuple[tuple[int, float, list[int]], ...] = ((256, 0.2, [64, 128]), (128, 0.25, [128, 256])),
                 global_mlp: tuple[int, ...] = (256, 512), norm: bool = True) -> None:
        super().__init__()
        sa, c = [], in_channels
        for npoint, radius, mlp in levels:
            sa.append(SetAbstraction(npoint, radius, nsample, c, mlp, norm))
            c = mlp[-1]
        sa.append(SetAbstraction(None, None, nsample, c, list(global_mlp), norm))
        self.sa = nn.ModuleList(sa)
        self.out_channels = global_mlp[-1]
        self.level_channels = [in_channels] + [m.out_channels for m in sa]

    def group(self, xyz: Tensor) -> list[Grouping | None]:
        """All levels' groupings for xyz (B,N,3): they depend on the geometry only, so two encoders can share them."""
        _check_points(xyz)
        least = self.sa[0].npoint or 1
        if xyz.shape[1] < least:
            raise ValueError(f"xyz: expected at least {least} points (the first set-abstraction level samples "
                             f"{least} centres), got {xyz.shape[1]}")
        out, cur = [], xyz
        for sa in self.sa:
            g = sa.group(cur)
            out.append(g)
            if g is not None:
                cur = gather(cur, g.centres)
        return out

    def forward(self, xyz: Tensor, features: Tensor | None = None,
                groupings: list[Grouping | None] | None = None) -> PointNet2Output:
        """xyz (B,N,3), features (B,N,C) -> PointNet2Output (levels 0..3, the last one global (B,1,C_out))."""
        _check_points(xyz)
        if features is not None and (features.shape[:2] != xyz.shape[:2]):
            raise ValueError(f"features: expected shape (B, N, C) with (B, N) = {tuple(xyz.shape[:2])}, "
                             f"got {tuple(features.shape)}")
        groupings = groupings if groupings is not None else self.group(xyz)
        xs, fs = [xyz], [features]
        for sa, g in zip(self.sa, groupings):
            x, f = sa(xs[-1], fs[-1], g)
            xs.append(x)
            fs.append(f)
        return PointNet2Output(xs, fs)
