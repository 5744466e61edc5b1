"""``python -m eha_app.cli``: the same as the ``eha`` command."""

import sys

from eha_app.cli import main

sys.exit(main())
