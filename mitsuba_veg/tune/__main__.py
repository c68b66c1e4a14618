"""``python -m mitsuba_veg.tune SCENARIO.toml --target ...``: the ``tune`` command
(:mod:`mitsuba_veg.cli.tune`) as a module entry point."""
import sys

from ..cli.tune import main

sys.exit(main())
