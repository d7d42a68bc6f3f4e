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
        self.message = message
        super().__init__(f"{field}: {message}")

    def __reduce__(self):
        # Pickled across a process boundary (a simulation worker's error reaching the service):
        # rebuilt from the field, the message and the attributes, whatever the subclass's own
        # constructor takes, so that the error arrives intact and the pool is not broken.
        return _rebuild_input_error, (type(self), self.field, self.message, self.__dict__)


def _rebuild_input_error(
    cls: type[InvalidInputError], field: str, message: str, state: dict
) -> InvalidInputError:
    error = cls.__new__(cls)
    InvalidInputError.__init__(error, field, message)
    error.__dict__.update(state)
    return error


class SceneError(InvalidInputError):
    """A scene file or scene specification is invalid."""
