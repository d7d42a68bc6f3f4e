"""The doctests of this package need the ``bluesky`` extra (bluesky, ophyd-async): where it is
not installed (the floors' venv installs ``.[dev]`` only) its modules are not collected."""

import importlib.util

collect_ignore_glob = [] if importlib.util.find_spec("ophyd_async") else ["*.py"]
