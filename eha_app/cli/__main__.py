"""``python -m eha_app.cli``: the same as the ``eha`` command.

Nothing runs on a plain import: Panel's ``/components/`` route once imported
this module by name from a URL, and the server re-read its own command line
and exited.
"""

import sys

from eha_app.cli import main

if __name__ == "__main__":
    sys.exit(main())
