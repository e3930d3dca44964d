"""Argument checks shared by the one-call entry points: each raises an error naming the argument and what was expected,
before any work is done."""
from __future__ import annotations

import math
import numbers
import os
import sys
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import torch


def check_int(value: Any, name: str, least: int = 0) -> int:
    """value as an int >= least (bools and fractions refused)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < least:
        raise ValueError(f"{name}: expected an integer >= {least}, got {value!r}")
    return int(value)


def seeded_rng(seed: Any, name: str = "seed") -> np.random.Generator:
    """np.random.default_rng(seed) for an integer seed >= 0; None (which numpy would seed from the OS), bools and
    fractions are refused: the same call must give the same numbers."""
    return np.random.default_rng(check_int(seed, name))


def check_steps(steps: Any, name: str, count: int) -> tuple[int, ...]:
    """A tuple of `count` step counts >= 0."""
    try:
        out = tuple(steps)
    except TypeError:
        out = ()
    if len(out) != count or any(isinstance(s, bool) or not isinstance(s, numbers.Integral) or s < 0 for s in out):
        raise ValueError(f"{name}: expected {count} step counts (integers >= 0), got {steps!r}")
    return tuple(int(s) for s in out)


def check_positive(value: Any, name: str, most: float = math.inf, unit: str = "m") -> float:
    """A finite real in (0, most]."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) \
            or not 0 < value <= most:
        bound = "" if math.isinf(most) else f", at most {most:g}"
        raise ValueError(f"{name}: expected a finite positive number ({unit}){bound}, got {value!r}")
    return float(value)


def check_real(value: Any, name: str, what: str, positive: bool = False) -> float:
    """A finite real number (a Python or numpy number, or a one-element tensor), > 0 with `positive`; `what` says what
    was expected."""
    try:
        v = float(value) if not isinstance(value, (bool, str, bytes)) else math.nan
    except (TypeError, ValueError, RuntimeError):
        v = math.nan
    if not math.isfinite(v) or (positive and v <= 0):
        raise ValueError(f"{name}: expected {what}, got {value!r}")
    return v


def check_rotation(R: Any, name: str) -> None:
    """Finite rotation matrices (..., 3, 3): orthonormal, determinant +1 (a scale, shear or mirror would make an object's
    grid read another object)."""
    check_finite(R, name, "rotation matrices")
    Rd = torch.as_tensor(R).double()
    if not (torch.allclose(Rd @ Rd.transpose(-1, -2), torch.eye(3, dtype=Rd.dtype).expand_as(Rd), atol=1e-4)
            and bool((torch.linalg.det(Rd) > 0).all())):
        raise ValueError(f"{name}: expected a rotation matrix (orthonormal, determinant +1)")


def check_weight(value: Any, name: str) -> float:
    """A finite real >= 0 (a loss weight)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) or value < 0:
        raise ValueError(f"{name}: expected a finite number >= 0, got {value!r}")
    return float(value)


def check_finite(x: Any, name: str, what: str) -> None:
    """x (a tensor or array) without NaN or Inf; `what` says what was expected."""
    if not bool(torch.isfinite(torch.as_tensor(x)).all()):
        raise ValueError(f"{name}: contains NaN or Inf (expected {what})")


BETA_RANGE = 2.0   # shape coefficients the body was checked for (docs/body_model.md) and the training data drew


def check_betas(betas: Any, least: int) -> np.ndarray:
    """Shape coefficients as a float64 1-D array of at least `least` finite values; a ShapeWarning (a GraspkitWarning)
    for one beyond ±BETA_RANGE."""
    b = np.asarray(betas, np.float64)
    if b.ndim != 1 or len(b) < least or not np.isfinite(b).all():
        raise ValueError(f"betas: expected at least {least} finite shape coefficients (a 1-D array), got shape "
                         f"{np.shape(betas)}{'' if np.isfinite(b).all() else ' with NaN or Inf'}")
    k = int(np.abs(b).argmax()) if len(b) else 0
    if len(b) and abs(b[k]) > BETA_RANGE:
        warnings.warn(f"betas: coefficient {k} is {b[k]:g}, outside the ±{BETA_RANGE:g} the body was checked for and "
                      "the training data drew (docs/body_model.md); expect an odd body (all ten at -5: 0.94 m tall, "
                      "2 L) and the models to do worse", ShapeWarning, stacklevel=user_stacklevel())
    return b


def check_labels(x: Any, name: str) -> None:
    """x (a tensor) of float contact labels in [0, 1] (a bool mask is refused: the losses subtract it)."""
    if not x.is_floating_point() or bool(((x < 0) | (x > 1)).any()):
        raise ValueError(f"{name}: expected float contact labels in [0, 1] (a bool mask: .float())")


def check_seed(value: Any, name: str = "seed") -> int:
    """A seed as numpy's SeedSequence and torch take it: an integer in [0, 2^63) (bools refused)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not 0 <= value < 2**63:
        raise ValueError(f"{name}: expected a non-negative integer below 2^63, got {value!r}")
    return int(value)


def check_probabilities(x: Any, name: str) -> None:
    """x (a tensor or None) with every value in [0, 1] (NaN fails too): a contact map, say."""
    if x is not None and not bool(((x >= 0) & (x <= 1)).all()):
        raise ValueError(f"{name}: expected contact probabilities in [0, 1], got values from {float(x.min()):g} to "
                         f"{float(x.max()):g}")


def check_bool(value: Any, name: str) -> bool:
    """A real bool (a string such as 'no' would read as True)."""
    if not isinstance(value, bool):
        raise ValueError(f"{name}: expected True or False, got {value!r}")
    return value


def check_type(value: Any, cls: type, name: str, optional: bool = False, what: str | None = None) -> None:
    """value an instance of cls (or None when optional), else a TypeError naming the argument and the class (`what`,
    default its module path)."""
    if not (isinstance(value, cls) or (optional and value is None)):
        what = what or f"{cls.__module__}.{cls.__qualname__}"
        raise TypeError(f"{name}: expected a {what}{' or None' if optional else ''}, got {type(value).__name__}")


def check_generator(generator: Any, name: str = "generator") -> None:
    """None or a torch.Generator."""
    check_type(generator, torch.Generator, name, optional=True, what="torch.Generator")


# argparse types: a bad value becomes "argument --flag: ..." and exit code 2
def float_type(low: float, strict: bool) -> Callable[[str], float]:
    """An argparse type for finite floats above low (strict) or at least low."""
    import argparse

    def parse(text: str) -> float:
        v = float(text)
        if not math.isfinite(v) or v < low or (strict and v == low):
            raise argparse.ArgumentTypeError(f"expected a finite number {'>' if strict else '>='} {low:g}, got {text}")
        return v
    parse.__name__ = f"number {'>' if strict else '>='} {low:g}"
    return parse


nonneg_float = float_type(0.0, strict=False)     # loss weights, noise
positive_float = float_type(0.0, strict=True)    # time limits, learning rates


def count_type(least: int) -> Callable[[str], int]:
    """An argparse type for integers >= least."""
    import argparse

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer >= {least}, got {text}") from None
        if v < least:
            raise argparse.ArgumentTypeError(f"expected an integer >= {least}, got {text}")
        return v
    parse.__name__ = f"integer >= {least}"
    return parse


class GraspkitWarning(UserWarning):
    """graspkit's own warnings (the command line shows them as `graspkit: note: ...` lines)."""


class ShapeWarning(GraspkitWarning):
    """Shape coefficients beyond ±BETA_RANGE (check_betas)."""


_INSIDE = (os.path.dirname(os.path.abspath(__file__)) + os.sep,              # graspkit's folder, torch's
           os.path.dirname(os.path.abspath(torch.__file__)) + os.sep)


def user_stacklevel() -> int:
    """warnings.warn's stacklevel that points at the first frame outside graspkit and torch (the user's line, past
    graspkit's own callers and torch's no_grad wrappers), for
    warnings.warn(msg, GraspkitWarning, stacklevel=user_stacklevel())."""
    frame, level = sys._getframe(1), 1
    while frame.f_back is not None and os.path.abspath(frame.f_code.co_filename).startswith(_INSIDE):
        frame, level = frame.f_back, level + 1
    return level

