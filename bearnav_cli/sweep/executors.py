"""Where a sweep's work runs: a local process pool (``--jobs``) or a Dask cluster (``--scheduler``)."""

from __future__ import annotations

import socket
from collections.abc import Callable
from typing import Any

from bearnav_cli.errors import BearnavError
from bearnav_cli.sweep.work import one_line

__all__ = ["connect_scheduler", "local_executor", "SCHEDULER_TIMEOUT_S", "stop_local"]


#: Seconds ``--scheduler`` may take to answer before the sweep gives up (the issue's limit is 10 s).
SCHEDULER_TIMEOUT_S = 6.0


def _worker_signals() -> None:
    """A local worker leaves Ctrl-C to the sweep, which stops it (:func:`stop_local`); SIGTERM ends it at once.

    A forked worker inherits the command line's handlers, which turn both signals into exceptions
    that a long job may not see for seconds.
    """
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def local_executor(jobs: int) -> Any:
    """A :class:`concurrent.futures.ProcessPoolExecutor` of ``jobs`` processes (``--jobs``)."""
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(max_workers=jobs, initializer=_worker_signals)


def stop_local(executor: Any, interrupted: bool) -> None:
    """Shut a :func:`local_executor` down: wait for it after a sweep, end its workers at once after an interrupt."""
    if not interrupted:
        executor.shutdown(wait=True)
        return
    # the executor has no public way to end running jobs: its worker processes (a CPython attribute since 3.2)
    for process in list((getattr(executor, "_processes", None) or {}).values()):
        process.terminate()
    executor.shutdown(wait=True, cancel_futures=True)


def connect_scheduler(address: str, timeout: float = SCHEDULER_TIMEOUT_S) -> tuple[Any, Callable[[], None]]:
    """Dask's executor on the scheduler at ``address`` (``--scheduler``), and a function that closes it.

    Only here is ``distributed`` imported (``bearnav[dask]``). A refused or unknown address fails at
    once, a silent one after ``timeout`` seconds.

    Raises
    ------
    BearnavError
        ``distributed`` is not installed, or the scheduler cannot be reached (naming the address).
    """
    try:
        from distributed import Client
    except ImportError:
        raise BearnavError("--scheduler: needs Dask's distributed (pip install 'bearnav[dask]')") from None
    host_port = address.split("://", 1)[-1]
    host, _, port = host_port.rpartition(":")
    try:  # a plain TCP probe first: a refused port or an unknown host answers at once
        socket.create_connection((host.strip("[]") or "127.0.0.1", int(port)), timeout=timeout).close()
    except (OSError, ValueError) as exc:
        raise BearnavError(f"--scheduler: cannot reach the Dask scheduler at {address} ({one_line(exc)})") from None
    try:
        client = Client(address, timeout=f"{timeout}s")
    except Exception as exc:  # noqa: BLE001 - OSError, TimeoutError, whatever the protocol says: one line
        raise BearnavError(f"--scheduler: cannot reach the Dask scheduler at {address} ({one_line(exc)})") from None
    return client.get_executor(), client.close
