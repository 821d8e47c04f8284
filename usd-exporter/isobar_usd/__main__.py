"""``python -m isobar_usd``: the isobar-usd command line."""

import sys

from .cli import main

sys.exit(main())
