"""``python -m toftwin_cli``: the ``toftwin`` command."""

from toftwin_cli import main

main()
