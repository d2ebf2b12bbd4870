"""``python -m fnnbook``: same as the ``fnn-pipeline`` command."""

import sys

from fnnbook.cli import main

sys.exit(main())
