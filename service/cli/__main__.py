"""``python -m service.cli``: the ``toftwin`` command."""

from service.cli import main

main()
