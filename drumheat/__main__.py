"""``python -m drumheat ...`` runs the ``drumheat`` command (drumheat.cli)."""

from drumheat.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
