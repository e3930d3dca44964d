"""Give the caller's global torch state back after a library call that sets its own.

Training seeds torch's global generator (weights' initialisation, dropout), building a model to load a checkpoint
into draws initial weights from it, and the commands fix their thread count; a function that does any of these as a
library call (fit, the evaluators, every load_* of a checkpoint) restores both when it returns, so that a notebook's
later draws and timings do not depend on having called it (the training itself is unchanged: it seeds as before).
"""
from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

import torch

F = TypeVar("F", bound=Callable[..., Any])


@contextmanager
def kept_torch_state() -> Iterator[None]:
    """Inside the block torch's global CPU generator and intra-op thread count may change; after it they are back."""
    threads = torch.get_num_threads()
    with torch.random.fork_rng(devices=[]):
        try:
            yield
        finally:
            if torch.get_num_threads() != threads:
                torch.set_num_threads(threads)


def keeps_torch_state(fn: F) -> F:
    """Decorator: fn runs inside kept_torch_state()."""
    @functools.wraps(fn)
    def wrapped(*args: Any, **kwargs: Any) -> Any:
        with kept_torch_state():
            return fn(*args, **kwargs)
    return wrapped  # type: ignore[return-value]
