"""``python -m sb3_genrl.cli``: the ``genrl`` command line."""

import sys

from sb3_genrl.cli import main

sys.exit(main())
