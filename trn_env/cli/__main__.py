"""`python -m trn_env.cli`: the `trn-env` command."""

import sys

from trn_env.cli import main

sys.exit(main())
