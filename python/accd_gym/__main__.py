"""``python -m accd_gym`` runs the ``accd-gym`` command line."""

from accd_gym.cli import run

run()
