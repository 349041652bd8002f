"""``python -m bve_mj.cli``: the same as ``bve-mj``."""

import sys

from bve_mj.cli import main

sys.exit(main())
