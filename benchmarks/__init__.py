"""The benchmarks behind ``toftwin bench``: figures of the renderer and of the service.

- :mod:`benchmarks.renderer`: the renderer alone (``render``, ``accuracy``, ``mitsuba``,
  ``ground-test``); these import sim_core and nothing else of the project;
- :mod:`benchmarks.campaign`: a campaign on the simulated rig, through the service;
- :mod:`benchmarks.cli`: the ``toftwin bench`` command group.

The package sits above the service (the service never imports it); :mod:`toftwin_cli` adds the
command group to the ``toftwin`` command. ``lint-imports`` checks both rules.
"""
