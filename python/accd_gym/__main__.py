"""``python -m accd_gym`` runs the ``accd-gym`` command line."""

import sys

from accd_gym.cli import main

sys.exit(main())
