"""`python -m veg_area_ros.cli`: the `veg-area` command."""

import sys

from ..launcher import main

sys.exit(main())
