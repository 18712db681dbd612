"""``python -m torch_eigview`` runs the ``eigview`` command."""

import sys

from torch_eigview.apps.cli import main

sys.exit(main())
