"""``python -m simreal_nodes.cli``: the `simreal` command without the installed script (tests, fresh checkouts)."""

import sys

from simreal_nodes.cli import main

sys.exit(main())
