"""Every setting is documented in docs/service.md's settings table."""

from __future__ import annotations

import re
from pathlib import Path

from service.settings import Settings

SERVICE_DOC = Path(__file__).resolve().parents[2] / "docs" / "service.md"


def settings_section(markdown: str) -> str:
    """The text of the ``## Settings`` section."""
    m = re.search(r"^## Settings\n(.*?)(?=^## )", markdown, flags=re.M | re.S)
    assert m, f"{SERVICE_DOC.name} has no '## Settings' section"
    return m.group(1)


def test_every_setting_is_documented():
    section = settings_section(SERVICE_DOC.read_text(encoding="utf-8"))
    words = {w for span in re.findall(r"`([^`]+)`", section) for w in re.findall(r"\w+", span)}
    missing = [name for name in Settings.model_fields
               if f"TOFTWIN_{name.upper()}" not in words and name not in words]
    assert not missing, (
        f"Settings fields (service/settings.py) missing from the settings table of "
        f"{SERVICE_DOC.name}: {missing}; add TOFTWIN_<FIELD> with its default and meaning")
