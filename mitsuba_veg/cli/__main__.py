"""``python -m mitsuba_veg.cli ...``: the ``mitsuba-veg`` command."""
import sys

from .command import main

sys.exit(main())
