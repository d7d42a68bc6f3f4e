"""Errors of the service layer and the HTTP status each maps to.

Input errors are :class:`sim_core.errors.InvalidInputError` (422, its message names the field
and the allowed range); device faults are :class:`drivers.errors.DeviceError` (503, the
device's own message). The classes here cover the rest.
"""

from __future__ import annotations


class ServiceError(Exception):
    """An error with an HTTP status."""

    status_code = 500

    def __init__(self, detail: str) -> None:
        self.detail = detail
        super().__init__(detail)


class NotFoundError(ServiceError):
    """No such campaign, frame or result."""

    status_code = 404


class ConflictError(ServiceError):
    """The request does not fit the current state (a campaign holds the rig, wrong state)."""

    status_code = 409


class UnavailableError(ServiceError):
    """A device or the executor is not available."""

    status_code = 503


class GoneError(ServiceError):
    """The resource is known but its files are gone from the data directory."""

    status_code = 410


class InsufficientStorageError(ServiceError):
    """The data directory's disk is (nearly) full."""

    status_code = 507
