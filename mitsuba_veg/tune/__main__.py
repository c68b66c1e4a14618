"""``python -m mitsuba_veg.tune SCENARIO.toml --target ...`` (see :mod:`mitsuba_veg.tune.cli`)."""
import sys

from .cli import main

sys.exit(main())
