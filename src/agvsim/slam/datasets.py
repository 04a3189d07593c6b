"""Where the third-party SLAM data sets are (never copied into the repository).

``$AGVSIM_DATASETS`` if set, else ``<repo root>/../shared/datasets`` (repo root: the folder
holding ``src/``); ``None`` when that folder does not exist, so benchmarks and opt-in tests
can skip cleanly.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["ENV_VAR", "datasets_dir"]

ENV_VAR = "AGVSIM_DATASETS"
_REPO_ROOT = Path(__file__).resolve().parents[3]  # src/agvsim/slam/datasets.py -> repo root


def datasets_dir() -> Path | None:
    """The data-sets folder (``$AGVSIM_DATASETS`` or ``<repo>/../shared/datasets``), or None."""
    env = os.environ.get(ENV_VAR)
    path = Path(env).expanduser() if env else _REPO_ROOT.parent / "shared" / "datasets"
    return path if path.is_dir() else None
