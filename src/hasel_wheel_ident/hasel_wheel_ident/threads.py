"""The threads the identification shares (no rclpy, no ROS).

* :func:`window_pool`: the worker threads a problem splits its shooting windows over.  The
  compiled simulator releases the GIL, so two threads on two cores nearly halve a fit.
* :func:`one_blas_thread`: OpenBLAS keeps its own worker threads spinning for a while after
  every call.  The fit's linear algebra is small (an SVD of n x g with g <= 20), and those
  spinning threads take the core that the other shooting thread needs: a fit on 5 x 60 s ran
  in 5.5 s with them and in 3.7 s without (OpenBLAS limited to one thread).  The limit is held
  while identification work started from the main thread runs, and lifted after it.
  Without threadpoolctl (pip ``threadpoolctl``, apt ``python3-threadpoolctl``) it is a no-op:
  the same results, only slower.
"""
from __future__ import annotations

import functools
import os
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor, wait
from contextlib import contextmanager
from typing import Any, TypeVar

try:
    from threadpoolctl import threadpool_limits
except ImportError:                      # optional: only the speed depends on it
    threadpool_limits = None

_POOL: list[ThreadPoolExecutor] = []
_LOCK = threading.Lock()
_HOLDERS = {"depth": 0, "limiter": None}

F = TypeVar("F", bound=Callable[..., Any])
T = TypeVar("T")


def _cores() -> int:
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:                       # not on Linux
        return os.cpu_count() or 1


def window_pool() -> ThreadPoolExecutor:
    """The process-wide worker threads, one per usable core, never shut down (a forked child
    starts a fresh pool).  Give them leaf tasks only: a task that waits on another task of
    the same pool could wait forever."""
    with _LOCK:
        if not _POOL:
            _POOL.append(ThreadPoolExecutor(max_workers=_cores(), thread_name_prefix="ident"))
        return _POOL[0]


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_POOL.clear)


def run_split(fn: Callable[[T], None], parts: list[T]) -> None:
    """``fn(part)`` for every part: the first in the calling thread, the rest on
    :func:`window_pool`.  Returns once all have finished (also when one raised, so that none
    is still writing into shared arrays), and re-raises the first error."""
    pending = [window_pool().submit(fn, part) for part in parts[1:]]
    try:
        if parts:
            fn(parts[0])
    finally:
        wait(pending)
    for f in pending:
        f.result()


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Hold BLAS to one thread in this block (re-entrant).

    Only the main thread sets and lifts the limit (the limit is process-wide, so it covers
    the worker threads the main thread's work starts).  OpenBLAS did not always honour a
    limit set in one thread and lifted in another, so a block entered from any other thread
    changes nothing."""
    if threadpool_limits is None or threading.current_thread() is not threading.main_thread():
        yield
        return
    if _HOLDERS["depth"] == 0:
        _HOLDERS["limiter"] = threadpool_limits(limits=1, user_api="blas")
    _HOLDERS["depth"] += 1
    try:
        yield
    finally:
        _HOLDERS["depth"] -= 1
        if _HOLDERS["depth"] == 0:
            _HOLDERS["limiter"].restore_original_limits()
            _HOLDERS["limiter"] = None


def with_one_blas_thread(fn: F) -> F:
    """Decorator: run ``fn`` under :func:`one_blas_thread`."""
    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with one_blas_thread():
            return fn(*args, **kwargs)
    return wrapper  # type: ignore[return-value]
