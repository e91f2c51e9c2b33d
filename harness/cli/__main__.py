"""``python -m harness.cli``: the ``denoise-bench`` command."""

import sys

from harness.cli import main

sys.exit(main())
