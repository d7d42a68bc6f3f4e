"""Errors of the service layer, each naming its problem type.

Input errors are :class:`sim_core.errors.InvalidInputError` (422, its message names the field
and the allowed range); device faults are :class:`drivers.errors.DeviceError` (503, the
device's own message). The classes here cover the rest. The API answers each as an RFC 9457
problem (:mod:`service.api.problems`) of type ``urn:toftwin:problem:<problem>``, with the HTTP
status and ``title`` that problem type's table holds and the error's message as its ``detail``.
"""

from __future__ import annotations


class ServiceError(Exception):
    """An error the API answers as the problem type ``problem``."""

    #: the problem type's last part (``urn:toftwin:problem:<problem>``): a key of
    #: :data:`service.api.problems.PROBLEM_TYPES`, which holds its HTTP status and title
    problem = "internal-error"

    def __init__(self, detail: str) -> None:
        self.detail = detail
        super().__init__(detail)


class NotFoundError(ServiceError):
    """No such campaign, frame or result."""

    problem = "not-found"


class ConflictError(ServiceError):
    """The request does not fit the current state (a campaign holds the rig, wrong state)."""

    problem = "conflict"


class UnavailableError(ServiceError):
    """A device or the executor is not available."""

    problem = "unavailable"


class GoneError(ServiceError):
    """The resource is known but its files are gone from the data directory."""

    problem = "gone"


class DamagedFileError(GoneError):
    """A stored file of the resource is there but cannot be read (truncated, corrupt)."""

    problem = "damaged-file"


class InsufficientStorageError(ServiceError):
    """The data directory's disk is (nearly) full."""

    problem = "insufficient-storage"
