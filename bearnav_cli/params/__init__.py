"""Each parameter declared once (issue 24): the ``Params`` dataclass of every stage and of ``verify``.

A field is declared with :func:`~bearnav_cli.params.declare.param`: its default, its documented range
(:class:`~bearnav_cli.params.declare.Range`), its choices, its unit and its command-line option, in the
field's metadata. :data:`bearnav_cli.limits.LIMITS`, the command line's options
(:mod:`bearnav_cli.cli.fields`) and docs/cli.md's tables are made of it.

The modules import the standard library, :mod:`bearnav_cli.errors` and the numpy-free
:mod:`bearnav_cli.runtime.defaults` only, so that the command line reads a command's fields by importing them
(``bearnav simulate --help`` imports no numpy). Each stage re-exports its ``Params`` (``stages.rrtstar.Params``).
"""

#: The module of each command's ``Params`` (the stage table's, plus ``verify``).
MODULES = {
    "map": "bearnav_cli.params.map_", "rrtstar": "bearnav_cli.params.rrtstar",
    "simplify": "bearnav_cli.params.simplify", "decompose": "bearnav_cli.params.decompose",
    "synthesize": "bearnav_cli.params.synthesize", "simulate": "bearnav_cli.params.simulate",
    "verify": "bearnav_cli.params.verify",
}  # fmt: skip

__all__ = ["MODULES"]
