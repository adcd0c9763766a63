"""`python -m sketchrodgs` is the `sketchrodgs` command."""

import sys

from .cli import main

sys.exit(main())
