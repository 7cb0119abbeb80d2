"""One module per pipeline stage; each exposes ``VERSION``, a frozen ``Params`` and ``run``."""
