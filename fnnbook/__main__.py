"""``python -m fnnbook``: same as the ``fnn-pipeline`` command."""

import sys

from fnnbook.entry import main

sys.exit(main())
