"""``python -m slopedist`` runs the command line."""

import sys

from slopedist.cli import main

sys.exit(main())
