"""Errors of the service layer, the HTTP status each maps to and its problem type.

Input errors are :class:`sim_core.errors.InvalidInputError` (422, its message names the field
and the allowed range); device faults are :class:`drivers.errors.DeviceError` (503, the
device's own message). The classes here cover the rest. The API answers each as an RFC 9457
problem (:mod:`service.api.problems`) of type ``urn:toftwin:problem:<problem>`` with ``title``
and the error's message as its ``detail``.
"""

from __future__ import annotations


class ServiceError(Exception):
    """An error with an HTTP status."""

    status_code = 500
    #: the problem type's last part (``urn:toftwin:problem:<problem>``) and its title
    problem = "internal-error"
    title = "Internal server error"

    def __init__(self, detail: str) -> None:
        self.detail = detail
        super().__init__(detail)


class NotFoundError(ServiceError):
    """No such campaign, frame or result."""

    status_code = 404
    problem = "not-found"
    title = "Not found"


class ConflictError(ServiceError):
    """The request does not fit the current state (a campaign holds the rig, wrong state)."""

    status_code = 409
    problem = "conflict"
    title = "Conflict"


class UnavailableError(ServiceError):
    """A device or the executor is not available."""

    status_code = 503
    problem = "unavailable"
    title = "Service unavailable"


class GoneError(ServiceError):
    """The resource is known but its files are gone from the data directory."""

    status_code = 410
    problem = "gone"
    title = "Gone"


class DamagedFileError(GoneError):
    """A stored file of the resource is there but cannot be read (truncated, corrupt)."""

    problem = "damaged-file"
    title = "Damaged file"


class InsufficientStorageError(ServiceError):
    """The data directory's disk is (nearly) full."""

    status_code = 507
    problem = "insufficient-storage"
    title = "Insufficient storage"
