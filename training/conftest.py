"""Makes `conesight_train` importable when pytest runs from the repo root without an install."""

import sys
from pathlib import Path

_TRAINING_DIR = str(Path(__file__).resolve().parent)
if _TRAINING_DIR not in sys.path:
    sys.path.insert(0, _TRAINING_DIR)
