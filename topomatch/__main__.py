"""``python -m topomatch``: the command line."""

import sys

from topomatch.pipeline.cli import main

sys.exit(main())
