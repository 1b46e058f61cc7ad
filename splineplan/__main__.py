"""``python -m splineplan``."""

import sys

from splineplan.cli import main

sys.exit(main())
