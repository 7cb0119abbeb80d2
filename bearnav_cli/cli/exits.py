"""Exit codes, and the one place that turns a command's failures into a line on stderr and an exit code.

Exit codes: 0 success, 1 the outcome failed (:data:`EXIT_OUTCOME`), 2 usage (click's own), 3 invalid
input (:data:`EXIT_INVALID`), 70 a bug of bearnav's own (:data:`EXIT_INTERNAL`), 130 SIGINT and
143 SIGTERM (:data:`EXIT_INTERRUPTED`, :data:`EXIT_TERMINATED`). An ``error:`` line is printed by
:func:`fail` and nowhere else, an interrupt's line by :func:`handles_errors` (``bearnav sweep`` says
itself how many of its jobs are stored).
"""

import atexit
import functools
import gc
import os
import signal
import sys
import threading
from typing import Any, Callable

import typer

from bearnav_cli.cli.output import err, setup_logging
from bearnav_cli.cli.startup import AS_PROGRAM
from bearnav_cli.errors import BearnavError, InternalError

__all__ = [
    "EXIT_INTERNAL",
    "EXIT_INTERRUPTED",
    "EXIT_INVALID",
    "EXIT_OUTCOME",
    "EXIT_TERMINATED",
    "Terminated",
    "exit_at_once",
    "fail",
    "handles_errors",
]


EXIT_OUTCOME, EXIT_INVALID, EXIT_INTERRUPTED, EXIT_TERMINATED = 1, 3, 130, 143
#: A bug of bearnav's own, never the user's input (EX_SOFTWARE of sysexits.h).
EXIT_INTERNAL = 70


def fail(message: str, code: int) -> typer.Exit:
    """Print ``error: MESSAGE`` on stderr, one line, and give the exit to raise: the one place that prints an error."""
    err.print(f"[red]error:[/red] {message}".replace("\n", " "), highlight=False, soft_wrap=True, markup=True)
    return typer.Exit(code)


class Terminated(KeyboardInterrupt):
    """SIGTERM, turned into an exception so that temp files are removed on the way out."""


_SIGNALLED: list[int] = []  # the signals that reached the running command, in order


def _raise_interrupt(signum: int, frame: object) -> None:
    _SIGNALLED.append(signum)
    raise KeyboardInterrupt if signum == signal.SIGINT else Terminated


def _as_interrupt(exc: BaseException) -> KeyboardInterrupt | None:
    """The interrupt behind ``exc``, when a signal reached the command while it raised.

    A signal that lands inside an extension module's import comes out as that import's
    ``ImportError: initialization failed`` (pybind11 wraps it): the user still pressed Ctrl-C.
    """
    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, KeyboardInterrupt):
            return seen
        seen = seen.__cause__ or seen.__context__
    if _SIGNALLED:
        return KeyboardInterrupt() if _SIGNALLED[-1] == signal.SIGINT else Terminated()
    return None


def _interrupt_message(command: str, exc: BaseException) -> str:
    from bearnav_cli import pipeline

    word = "terminated" if isinstance(exc, Terminated) else "interrupted"
    stage = pipeline.ACTIVITY.stage
    if stage is None:
        return f"{word}; nothing written for {command}"
    if pipeline.ACTIVITY.written:
        return f"{word}; {stage} was written, nothing after it"
    return f"{word}; nothing written for {stage}"


def _interrupted(command: str, exc: KeyboardInterrupt) -> typer.Exit:
    err.print(_interrupt_message(command, exc), highlight=False, soft_wrap=True, markup=False)
    return typer.Exit(EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED)


def handles_errors(command: Callable) -> Callable:
    """Turn every way a command can fail into one line on stderr and an exit code.

    bearnav errors exit 3 (invalid input); SIGINT exits 130 and SIGTERM 143 with ``interrupted;
    nothing written for STAGE`` (temp files are removed on the way); a broken invariant
    (:class:`InternalError`) and anything unexpected are internal errors, one line too, exit 70
    (``BEARNAV_TRACEBACK=1`` shows the traceback).
    """
    name = command.__name__.removesuffix("_command")

    @functools.wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        from bearnav_cli import pipeline

        if AS_PROGRAM and not gc.isenabled():  # the start-up's objects (cli.startup) stay out of every collection
            gc.freeze()
            gc.enable()
        setup_logging()
        pipeline.reset_activity()
        _SIGNALLED.clear()
        previous: dict[int, Any] = {}
        if threading.current_thread() is threading.main_thread():
            for signum in (signal.SIGINT, signal.SIGTERM):
                previous[signum] = signal.signal(signum, _raise_interrupt)
        try:
            return command(*args, **kwargs)
        except (typer.Exit, typer.Abort, typer.BadParameter):
            raise
        except InternalError as exc:
            raise fail(
                f"internal error (a bug in bearnav, not your input): {exc}".replace("[", r"\["), EXIT_INTERNAL
            ) from None
        except BearnavError as exc:
            raise fail(str(exc).replace("[", r"\["), EXIT_INVALID) from None
        except KeyboardInterrupt as exc:
            raise _interrupted(name, exc) from None
        except MemoryError:
            stage = pipeline.ACTIVITY.stage or name
            raise fail(f"out of memory in {stage}; nothing written for it (ask for less)", EXIT_INVALID) from None
        except Exception as exc:  # noqa: BLE001 - the last guard: one line, never a traceback
            interrupt = _as_interrupt(exc)
            if interrupt is not None:
                raise _interrupted(name, interrupt) from None
            if os.environ.get("BEARNAV_TRACEBACK"):
                raise
            stage = pipeline.ACTIVITY.stage or name
            text = f"internal error in {stage} ({type(exc).__name__}: {exc}); nothing written for it"
            raise fail(text.replace("[", r"\[") + " (BEARNAV_TRACEBACK=1 shows where)", EXIT_INTERNAL) from None
        finally:
            for signum, handler in previous.items():
                # the program ends now, its outcome decided: a late SIGINT must not turn it into a kill
                signal.signal(signum, signal.SIG_IGN if AS_PROGRAM else handler)

    return wrapper


def exit_at_once(code: Any) -> None:
    """End the program with ``code`` (a ``SystemExit``'s) without the interpreter's teardown.

    Called when the command line is done: every file it wrote is closed. Of a normal exit this keeps
    running the ``atexit`` functions and flushing stdout and stderr, and skips tearing down every module
    and object (``os._exit``), 20 ms of a ``bearnav rrtstar`` process after numpy, shapely and typer
    (bench/README.md "RRT* as whole processes"). It returns, for the normal exit, where that would differ:
    another thread still runs (the interpreter waits for it), ``code`` is not an exit status (Python
    prints it), or a stream cannot be flushed (Python reports it and exits 120).
    """
    if not (code is None or isinstance(code, int)) or threading.active_count() > 1:
        return
    atexit._run_exitfuncs()  # each runs once: they are unregistered as they run
    try:
        for stream in (sys.stdout, sys.stderr):
            if stream is not None:
                stream.flush()
    except (OSError, ValueError):  # a reader gone, a closed stream
        return
    os._exit(code or 0)
