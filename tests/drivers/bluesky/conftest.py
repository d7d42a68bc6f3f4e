"""The Bluesky devices' tests need the ``bluesky`` extra (bluesky, ophyd-async), as their mark
``bluesky`` says; where it is not installed (the floors' venv) they are not even collected, so
that ``-m "not bluesky"`` deselects nothing that would fail to import."""

from __future__ import annotations

import importlib.util

collect_ignore_glob = [] if importlib.util.find_spec("ophyd_async") else ["test_*.py"]
