"""``python -m backend`` runs the ``heliotwin`` CLI."""

import sys

from backend.cli import main

if __name__ == "__main__":
    sys.exit(main())
