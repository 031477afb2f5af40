"""``python -m gttnet`` (used by torchrun) runs the gttnet CLI."""

from gttnet.cli import main

main()
