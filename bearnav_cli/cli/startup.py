"""A signal while Python is still importing the command line: one line and the exit code, at once.

The package imports this module first, so that the handlers are in place before typer and the
rest load (a Ctrl-C then would otherwise print a traceback from the middle of an import).
"""

import gc
import os
import signal
import sys
import threading

__all__ = ["AS_PROGRAM", "release"]


def _interrupted_while_starting(signum: int, frame: object) -> None:
    """SIGINT or SIGTERM while Python is still importing: nothing has been read or written yet."""
    command = next((arg for arg in sys.argv[1:] if not arg.startswith("-")), "bearnav")
    word = "interrupted" if signum == signal.SIGINT else "terminated"
    os.write(2, f"{word}; nothing written for {command}\n".encode())
    os._exit(130 if signum == signal.SIGINT else 143)


#: Whether this process is the ``bearnav`` program (not a test or a library importing the module).
AS_PROGRAM = os.path.basename(sys.argv[0]) in ("bearnav", "__main__.py")
_STARTUP_HANDLERS: dict[int, object] = {}
if AS_PROGRAM:
    # the imports make about a million objects that all live to the end: collecting among them finds nothing
    # (6 ms of a start); a command freezes them and collects as usual from there (exits.handles_errors)
    gc.disable()
if threading.current_thread() is threading.main_thread():
    for _signum in (signal.SIGINT, signal.SIGTERM):
        _STARTUP_HANDLERS[_signum] = signal.signal(_signum, _interrupted_while_starting)


def release() -> None:
    """The imports are done: a test or a library that imported the app gets SIGINT and SIGTERM back.

    The program keeps the guard until a command installs its own handlers (``exits.handles_errors``).
    """
    if not AS_PROGRAM:
        for signum, handler in _STARTUP_HANDLERS.items():
            signal.signal(signum, handler)
