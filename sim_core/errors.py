"""Exceptions raised for invalid input.

Every message names the offending field, the value received and the allowed range, so that
the CLI can print it as it is (exit code 2) and the service can return it as HTTP 422.
"""

from __future__ import annotations


class ToftwinError(Exception):
    """Base class of every error this project raises on purpose."""


class InvalidInputError(ToftwinError, ValueError):
    """An input value is outside its allowed range or of the wrong form.

    Attributes
    ----------
    field : str
        Dotted path of the offending field, e.g. ``"illumination.power_w"``.
    """

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        super().__init__(f"{field}: {message}")


class SceneError(InvalidInputError):
    """A scene file or scene specification is invalid."""
