"""``python -m gttdata`` runs the gttdata CLI."""

from gttdata.cli import main

main()
