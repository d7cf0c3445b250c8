"""``python -m beltjax ...``: the same as the ``beltjax`` command (see :mod:`beltjax.cli`)."""

import sys

from beltjax.cli import main

sys.exit(main())
