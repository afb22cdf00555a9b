"""``python -m service.cli`` runs the ``finaldrive`` command line."""

import sys

from service.cli import main

sys.exit(main())
