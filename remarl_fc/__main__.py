"""``python -m remarl_fc``: the same as the ``remarl-fc`` command."""

import sys

from remarl_fc.cli import main

sys.exit(main())
