"""Fixtures for the driver tests: simulators served on real ptys, scripted pty peers."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from drivers.sim.pty_server import SimHandle, start_simulator
from tests.drivers.helpers import ScriptedPeer


@pytest.fixture
def scripted_peer() -> Iterator[type[ScriptedPeer]]:
    """Factory of :class:`ScriptedPeer`; every peer made is closed after the test."""
    made: list[ScriptedPeer] = []

    class _Peer(ScriptedPeer):
        def __init__(self, *args: object, **kwargs: object) -> None:
            super().__init__(*args, **kwargs)  # type: ignore[arg-type]
            made.append(self)

    yield _Peer
    for peer in made:
        peer.close()


@pytest.fixture
def turntable_sim() -> Iterator[SimHandle]:
    """SMC100 simulator on a pty, instant motions."""
    with start_simulator("turntable", instant=True) as handle:
        yield handle


@pytest.fixture
def solar_sim() -> Iterator[SimHandle]:
    """Solar simulator (lamp + shutter) on two ptys, instant warm-up."""
    with start_simulator("solar-simulator", instant=True) as handle:
        yield handle
