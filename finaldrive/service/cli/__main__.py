"""``python -m service.cli`` runs the ``finaldrive`` command line."""

import sys

from finaldrive.service.cli import main

sys.exit(main())
