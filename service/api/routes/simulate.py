"""``/api/v1/simulate``: one simulated frame, no hardware."""

from __future__ import annotations

from fastapi import APIRouter

from service.api.deps import ExecutorDep, SessionsDep, SettingsDep, StoreDep, TokenDep, errors
from service.api.schemas import SimulationPublic
from service.lab.requests import SimulationCreate
from service.lab.simulation import simulate_frame

router = APIRouter(tags=["simulation"])


@router.post("/simulate", response_model=SimulationPublic, status_code=201,
             responses=errors(401, 503, 507))
def create_simulation(
    body: SimulationCreate, sessions: SessionsDep, store: StoreDep, executor: ExecutorDep,
    settings: SettingsDep, _: TokenDep,
) -> dict:
    """Simulate a frame of a scene (bundled name or inline) at a turntable angle and level."""
    return simulate_frame(body, sessions=sessions, store=store, executor=executor,
                          settings=settings)
