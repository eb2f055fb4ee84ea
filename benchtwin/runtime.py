"""How benchtwin runs (not what it computes): the cores it may use, whether another process
already spreads its work over them, and the environment variables that tune it (``BENCHTWIN_SIM_FRAMES``, ``BENCHTWIN_SIM_FRAME_WORKERS``, ``BENCHTWIN_WORKERS``).

A tuning variable is an input like a command-line option: a bad value ends the command with exit
2 and a message naming the variable and what it expects (``EnvVarError`` is one of the CLI's
domain errors, benchtwin/cli.py), never as an internal error.
"""

from __future__ import annotations

import os


class EnvVarError(ValueError):
    """An environment variable with a value benchtwin cannot use (exit code 2)."""


def env_whole_number(name: str, what: str, minimum: int = 1) -> int | None:
    """The variable ``name`` as a whole number ≥ ``minimum``; None when unset or blank."""
    raw = os.environ.get(name, "").strip()
    if not raw:
        return None
    try:
        n = int(raw)
    except ValueError:
        n = None
    if n is None or n < minimum:
        raise EnvVarError(f"{name}={raw!r}: expected a whole number of {what} (≥ {minimum})")
    return n


def env_choice(name: str, choices: tuple[str, ...], default: str) -> str:
    """The variable ``name``, lower-cased, one of ``choices``; ``default`` when unset or blank."""
    raw = os.environ.get(name, "").strip().lower() or default
    if raw not in choices:
        raise EnvVarError(f"{name}={raw!r}: expected {', '.join(choices[:-1])} or {choices[-1]}")
    return raw


def in_pool_worker() -> bool:
    """Whether this process was started by multiprocessing (a design study's pool worker, a Dask
    worker): its parent already spreads the work over the cores, so it keeps to one (no frame
    workers, no settle worker, one analysis thread)."""
    import multiprocessing as mp

    return mp.parent_process() is not None or mp.current_process().daemon


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the OS has one, else the count)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1
