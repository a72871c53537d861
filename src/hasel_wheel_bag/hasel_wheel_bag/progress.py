"""The progress bar of the long-running commands (bag tools, demo, table2, trials, identify):
tqdm on stderr, left out when stderr is not a terminal (``test_progress.py``)."""
from __future__ import annotations

from typing import Iterable, Iterator, TypeVar

T = TypeVar("T")


def progress_bar(items: Iterable[T], label: str, total: float | None = None,
                 unit: str = " msg", scale: bool | float = True) -> Iterator[T]:
    """``items`` with a tqdm bar labelled ``label`` on stderr (left out when stderr is not a
    terminal).  ``scale``: True counts with SI prefixes (3.70k), False plainly, a number
    counts each item as that much of ``unit`` (e.g. the tick [s], to count seconds)."""
    from tqdm import tqdm
    fmt = None if isinstance(scale, bool) else \
        "{l_bar}{bar}| {n:.0f}/{total:.0f}{unit} [{elapsed}<{remaining}, {rate_fmt}]"
    with tqdm(items, desc=label, total=total, unit=unit, unit_scale=scale, disable=None,
              leave=False, mininterval=0.5, bar_format=fmt) as bar:
        yield from bar
