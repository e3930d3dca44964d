"""One switch for graspkit's progress bars (tqdm, on stderr): a bar is shown unless its call says progress=False or
the environment says TQDM_DISABLE=1 (tqdm's own variable, which `graspkit --quiet` sets for a whole command)."""
from __future__ import annotations

import os

QUIET_ENV = "TQDM_DISABLE"


def hidden(progress: bool = True) -> bool:
    """Whether a bar is off: progress False, or TQDM_DISABLE set to a true value (1, true, yes, on)."""
    return not progress or os.environ.get(QUIET_ENV, "").strip().lower() in ("1", "true", "yes", "on")
