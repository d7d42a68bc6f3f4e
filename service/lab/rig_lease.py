"""Who may use the rig now: a running campaign or calibration job, or one manual call at a time.

The rig itself serialises commands (:meth:`drivers.rig.Rig.hold`); the lease adds the service's
rule on top: while a campaign (or a calibration job) runs it owns the rig between its steps too,
so a manual call is refused with 409 instead of slipping in between two poses. The campaign
runner (the calibration jobs) claims the lease when a campaign (job) starts and releases it
when its thread ends; one holder at a time, of either kind. Manual calls
(:meth:`RigLease.manual`) check the claim before and after taking the rig's lock.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator

from drivers.errors import DeviceTimeoutError
from drivers.rig import Rig
from service.errors import ConflictError, UnavailableError


class RigLease:
    """The rig (or why there is none) and which campaign, if any, holds it.

    Parameters
    ----------
    rig : Rig or None
        None when the rig could not be opened; ``error`` says why.
    error : str or None
    wait_s : float
        How long a manual call waits for the rig's lock before answering 409.
    """

    def __init__(self, rig: Rig | None, error: str | None, wait_s: float) -> None:
        self.rig = rig
        self.error = error
        self.wait_s = wait_s
        self._lock = threading.Lock()
        #: (kind, id) of the holder: ("campaign", id) or ("calibration job", id)
        self._holder: tuple[str, str] | None = None

    @property
    def campaign_id(self) -> str | None:
        """The campaign that holds the rig, if any."""
        holder = self._holder
        return holder[1] if holder is not None and holder[0] == "campaign" else None

    @property
    def calibration_id(self) -> str | None:
        """The calibration job that holds the rig, if any."""
        holder = self._holder
        return holder[1] if holder is not None and holder[0] == "calibration job" else None

    def claim(self, holder_id: str, kind: str = "campaign") -> None:
        """A campaign (or a ``"calibration job"``) takes the rig (409 if another one has it)."""
        with self._lock:
            if self._holder is not None and self._holder != (kind, holder_id):
                held_kind, held_id = self._holder
                if held_kind == kind == "campaign":
                    raise ConflictError(
                        f"campaign {held_id} is running; one campaign at a time")
                raise ConflictError(
                    f"{held_kind} {held_id} is running and holds the rig; wait for it, or "
                    f"cancel it (POST /api/v1/{_route(held_kind)}/{held_id}/cancel)")
            self._holder = (kind, holder_id)

    def release(self, holder_id: str) -> None:
        """The holder gives the rig back (a no-op for another holder's id)."""
        with self._lock:
            if self._holder is not None and self._holder[1] == holder_id:
                self._holder = None

    def require(self) -> Rig:
        """The rig, or 503 naming why it is not there."""
        if self.rig is None:
            raise UnavailableError(f"rig not available: {self.error or 'not configured'}")
        return self.rig

    @contextlib.contextmanager
    def manual(self) -> Iterator[Rig]:
        """Hold the rig for a manual call; 409 while a campaign runs (checked under the lock)."""
        rig = self.require()
        self._refuse_if_campaign()
        with contextlib.ExitStack() as stack:
            try:
                stack.enter_context(rig.hold(timeout_s=self.wait_s))
            except DeviceTimeoutError as exc:  # the lock, not a device: another caller has it
                raise ConflictError(str(exc)) from None
            self._refuse_if_campaign()
            yield rig

    def _refuse_if_campaign(self) -> None:
        holder = self._holder
        if holder is not None:
            kind, held_id = holder
            what = "pause it" if kind == "campaign" else "cancel it"
            raise ConflictError(
                f"{kind} {held_id} is running and holds the rig; {what} or wait for it"
            )

    def close(self) -> None:
        """Close the rig's devices."""
        if self.rig is not None:
            self.rig.close()


def _route(kind: str) -> str:
    return "campaigns" if kind == "campaign" else "calibrations"
