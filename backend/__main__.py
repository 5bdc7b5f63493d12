"""``python -m backend`` runs the ``heliotwin`` CLI."""

import sys

from backend.cli import main

sys.exit(main())
