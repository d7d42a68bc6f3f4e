"""A conformance double of PMD's ``roypy`` (see :mod:`tests.roypy_double.roypy`).

This file makes the directory a package so that pytest's ``--doctest-modules`` collection imports
the double as ``tests.roypy_double.roypy`` and never as a top-level ``roypy``: a top-level
``roypy`` in ``sys.modules`` would make ``drivers.camera.royale`` believe royale is installed for
the rest of the session. To use it *as* ``roypy`` (a separate minimal venv, a manual session),
put this directory itself on ``sys.path`` / ``PYTHONPATH`` and ``import roypy``.
"""
