"""Progress over Monte Carlo runs: one bar a caller can share between scenarios (``fusionbench run all``).

The runners take ``progress``: None (a bar of their own on a terminal, nothing otherwise), a bool, or a bar
(anything with ``update(n)``) that they advance by the runs they finish and leave open.
"""

from __future__ import annotations

import os
import sys

from tqdm import tqdm


class _Shared:
    """A caller's bar: advanced here, closed by its owner."""

    def __init__(self, bar):
        self.bar = bar

    def update(self, n=1):
        self.bar.update(n)

    def close(self):
        pass


def bar(progress, total, desc):
    """The bar a runner advances by finished runs: the caller's (shared, left open) or its own."""
    if progress is not None and hasattr(progress, "update"):
        return _Shared(progress)
    show = sys.stderr.isatty() if progress is None else bool(progress)
    return terminal_bar(total, desc, disable=not show)


def terminal_bar(total, desc, disable):
    """A tqdm bar over runs on stderr: as wide as the terminal, or 100 x 20 where the terminal reports no size
    (a pseudo-terminal of ``script`` or a CI runner says 0 x 0, and tqdm then hides its bar as below the screen)."""
    try:
        size = os.get_terminal_size(sys.stderr.fileno())
    except (OSError, ValueError, AttributeError):  # not a terminal, or no file number
        size = os.terminal_size((0, 0))
    shape = {"dynamic_ncols": True} if size.columns > 0 and size.lines > 0 else {"ncols": 100, "nrows": 20}
    return tqdm(total=total, desc=desc, unit="run", disable=disable, **shape)


def expected_runs(scn, runs=None, quick=False):
    """Runs a scenario will finish (a conformance matrix: runs per condition x conditions)."""
    per = scn.sized(quick)[1] if runs is None else int(runs)
    return per * max(len(scn.conditions), 1)
