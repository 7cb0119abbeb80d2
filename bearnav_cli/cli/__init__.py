"""The ``bearnav`` command line (DESIGN §5): the only place that reads YAML, prints or exits.

Exit codes: 0 success (fresh stages included), 1 the run finished but the outcome failed (no
route), 2 usage, 3 invalid input (one line naming file, field or option and the problem),
130 interrupted (SIGINT: one line ``interrupted; nothing written for STAGE``), 143 terminated
(SIGTERM, the same line), 70 a bug of bearnav's own (:mod:`~bearnav_cli.cli.exits`).

One module per command (``map_``, ``stage``: rrtstar to synthesize, ``verify``, ``simulate``,
``plan``, ``inspect_``, ``tags``, ``plot``, ``sweep``), listed in :data:`~bearnav_cli.cli.main.COMMANDS` and
imported only when its command runs, shows its help or completes.
No module of the package uses ``from __future__ import annotations``: typer reads the annotations
of the command it runs on every start, and evaluating them from strings took 4 ms of it (the few names
imported for type checking are quoted). numpy, scipy, shapely, yaml, logging, rich, the stages and
the pipeline are imported inside the commands that use them, so that ``bearnav --help`` and
``bearnav inspect`` start at once (bench/README.md "Start-up"; tests/test_cli_startup.py).

``app`` is the program (``bearnav = "bearnav_cli.cli:app"``); ``read_map_source`` reads a map
YAML as ``bearnav plan`` does, for the benchmarks and tests. Python callers otherwise use the
stages, the pipeline and the runtime.
"""

# first: the start-up signal guard, before typer and the commands are imported
from bearnav_cli.cli import startup
from bearnav_cli.cli.main import app
from bearnav_cli.cli.mapfile import read_map_source

__all__ = ["app", "read_map_source"]

startup.release()
