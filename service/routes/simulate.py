"""``/api/v1/simulate``: one simulated frame, no hardware."""

from __future__ import annotations

from fastapi import APIRouter

from service.deps import CtxDep, TokenDep, errors
from service.schemas import SimulationCreate, SimulationPublic
from service.simulation import simulate_frame

router = APIRouter(tags=["simulation"])


@router.post("/simulate", response_model=SimulationPublic, status_code=201,
             responses=errors(401, 503))
def simulate(body: SimulationCreate, ctx: CtxDep, _: TokenDep) -> dict:
    """Simulate a frame of a scene (bundled name or inline) at a turntable angle and level."""
    return simulate_frame(ctx, body)
