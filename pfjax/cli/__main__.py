"""``python -m pfjax.cli``: the ``pfjax`` command."""

import sys

from pfjax.cli import main

sys.exit(main())
