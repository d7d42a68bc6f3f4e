"""Who may use the rig now: a running campaign, or one manual call at a time.

The rig itself serialises commands (:meth:`drivers.rig.Rig.hold`); the lease adds the service's
rule on top: while a campaign runs it owns the rig between its units too, so a manual call is
refused with 409 instead of slipping in between two poses. The campaign runner claims the lease
when a campaign starts and releases it when the campaign's thread ends; manual calls
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
        self._campaign_id: str | None = None

    @property
    def campaign_id(self) -> str | None:
        """The campaign that holds the rig, if any."""
        return self._campaign_id

    def claim(self, campaign_id: str) -> None:
        """A campaign takes the rig (409 if another one has it)."""
        with self._lock:
            if self._campaign_id is not None and self._campaign_id != campaign_id:
                raise ConflictError(
                    f"campaign {self._campaign_id} is running; one campaign at a time")
            self._campaign_id = campaign_id

    def release(self, campaign_id: str) -> None:
        """The campaign gives the rig back (a no-op for another campaign's id)."""
        with self._lock:
            if self._campaign_id == campaign_id:
                self._campaign_id = None

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
        active = self._campaign_id
        if active is not None:
            raise ConflictError(
                f"campaign {active} is running and holds the rig; pause it or wait for it"
            )

    def close(self) -> None:
        """Close the rig's devices."""
        if self.rig is not None:
            self.rig.close()
