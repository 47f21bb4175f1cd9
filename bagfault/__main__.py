"""`python -m bagfault`: the command line, as the `bagfault` script runs it."""

import sys

from bagfault.cli import main

sys.exit(main())
