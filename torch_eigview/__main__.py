"""``python -m torch_eigview`` runs the ``eigview`` command."""

import sys

from torch_eigview.cli import main

sys.exit(main())
