"""``python -m fnnlib.pipeline``: same as the ``fnn-pipeline`` command."""

import sys

from fnnlib.pipeline.cli import main

sys.exit(main())
