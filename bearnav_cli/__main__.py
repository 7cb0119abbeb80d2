"""``python -m bearnav_cli`` runs the command line."""

from bearnav_cli.cli import app

app(prog_name="bearnav")
