"""``python -m topomatch``: the command line."""

import sys

from topomatch.cli import main

sys.exit(main())
