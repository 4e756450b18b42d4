"""``python -m pfjax.cli``: the ``pfjax`` command."""

import sys

from pfjax.cli import main
from pfjax.interrupts import finished

sys.exit(finished(main()))  # a Ctrl-C after the command ended changes nothing
