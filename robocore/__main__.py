"""``python -m robocore`` runs the CLI."""

from robocore.cli import main

main()
