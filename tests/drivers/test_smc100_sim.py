"""The SMC100 simulator: states, TE letters, syntax tolerance, motion profile, client transcripts.

Most tests drive :meth:`Smc100Sim.handle_line` with a hand-stepped clock, so simulated time is
exact; the last ones go over a real pty with raw pyserial, byte for byte, replaying what
independent open-source clients send.
"""

from __future__ import annotations

import math
import time

import pytest
import serial

from drivers.sim import SimClock
from drivers.sim.faults import FaultInjector
from drivers.sim.pty_server import start_simulator
from drivers.sim.smc100 import Smc100Config, Smc100Sim, profile, trapezoid

pytestmark = pytest.mark.timeout(10)


class StepClock:
    """A wall clock the test advances by hand."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def make_sim(**config: object) -> tuple[Smc100Sim, StepClock]:
    wall = StepClock()
    sim = Smc100Sim(Smc100Config(**config), clock=SimClock(clock=wall))  # type: ignore[arg-type]
    return sim, wall


def ask(sim: Smc100Sim, line: str) -> str | None:
    replies = sim.handle_line(line)
    assert len(replies) <= 1
    return replies[0] if replies else None


def te(sim: Smc100Sim) -> str:
    reply = ask(sim, "1TE")
    assert reply is not None
    return reply[3:]


def home(sim: Smc100Sim, wall: StepClock) -> None:
    ask(sim, "1OR")
    wall.t += 100.0
    assert ask(sim, "1TS") == "1TS000032"


def make_homed_sim(**config: object) -> tuple[Smc100Sim, StepClock]:
    """A simulator homed, READY at 0 deg."""
    sim, wall = make_sim(**config)
    home(sim, wall)
    return sim, wall


# -- syntax --------------------------------------------------------------------------------
def test_power_up_state_and_queries_with_and_without_question_mark():
    sim, _ = make_sim()
    assert ask(sim, "1TS") == "1TS00000A"  # manual's TS example
    assert ask(sim, "1TS?") == "1TS00000A"
    assert ask(sim, "1ts") == "1TS00000A"  # upper and lower case are accepted
    assert ask(sim, "1 T S") == "1TS00000A"  # blanks are ignored anywhere
    assert ask(sim, "1VA?") == "1VA20"
    assert ask(sim, "1ID?") == "1IDURS100CC"


def test_blanks_inside_a_number_are_ignored():
    sim, _ = make_homed_sim()
    ask(sim, "1P A1.43 6")  # the manual's own example of "2P A1.43 6" == "2PA1.436"
    assert te(sim) == "@"
    assert ask(sim, "1PA?") == "1PA1.436"


@pytest.mark.parametrize(
    ("line", "letter", "homed"),
    [
        ("1XX", "A", False),  # unknown command
        ("1VB?", "X", False),  # stepper-only command on a CC controller
        ("1.5TS", "A", False),  # floating point controller address
        ("TS", "B", False),  # address missing
        ("32TS", "B", False),  # address out of range
        ("1PA10", "H", False),  # not referenced
        ("1VA10", "H", False),
        ("1MM0", "H", False),
        ("1PA", "C", True),  # parameter missing
        ("1VAabc", "C", True),
        ("1VA25", "C", True),  # above the configured maximum velocity
        ("1VA1e13", "C", True),  # out of range
        ("1OH5", "K", True),  # OH only in CONFIGURATION
    ],
)
def test_refused_commands_set_the_te_letter(line, letter, homed):
    sim, wall = make_sim()
    if homed:
        home(sim, wall)
    assert sim.handle_line(line) == []
    assert te(sim) == letter
    assert te(sim) == "@"  # TE clears the error buffer


def test_commands_for_another_address_are_ignored():
    sim, _ = make_sim()
    assert sim.handle_line("2TS") == []
    assert te(sim) == "@"


def test_tb_explains_current_or_given_error():
    sim, _ = make_sim()
    assert ask(sim, "1TB@") == "1TB@ No error"  # manual's TB example
    sim.handle_line("1XX")
    assert ask(sim, "1TB") == "1TBA Unknown message code or floating point controller address"
    assert te(sim) == "@"


# -- states --------------------------------------------------------------------------------
def test_homing_goes_through_1e_to_32_at_the_home_velocity():
    sim, wall = make_sim(initial_position_deg=12.5, home_velocity_deg_s=10.0)
    ask(sim, "1OR")
    assert ask(sim, "1TS") == "1TS00001E"
    ask(sim, "1OR")
    assert te(sim) == "E"  # home sequence already started
    wall.t += 0.5
    assert 0.0 < sim.current_position() < 12.5
    wall.t += 10.0
    assert ask(sim, "1TS") == "1TS000032"
    assert ask(sim, "1TP") == "1TP0"  # manual's TP example
    ask(sim, "1OR")
    assert te(sim) == "K"  # not allowed in READY


def test_move_goes_through_28_to_33_and_ends_exactly_on_target():
    sim, wall = make_homed_sim()
    ask(sim, "1PA45")
    assert ask(sim, "1TS") == "1TS000028"
    assert ask(sim, "1TH") == "1TH45"
    wall.t += 100.0
    assert ask(sim, "1TS") == "1TS000033"
    assert ask(sim, "1TP") == "1TP45"


def test_target_outside_software_limits_is_refused_with_g():
    sim, wall = make_homed_sim(limits_deg=(-170.0, 170.0))
    sim.handle_line("1PA170.5")
    assert te(sim) == "G"
    sim.handle_line("1PA170")
    assert te(sim) == "@"
    wall.t += 100.0
    sim.handle_line("1PR1")
    assert te(sim) == "G"


def test_software_limits_can_be_set_in_ready_but_not_past_the_set_point():
    sim, _ = make_homed_sim()
    ask(sim, "1SL-90")
    ask(sim, "1SR90")
    assert (ask(sim, "1SL?"), ask(sim, "1SR?"), te(sim)) == ("1SL-90", "1SR90", "@")
    sim.handle_line("1SL5")  # SL must be <= 0
    assert te(sim) == "C"


def test_disable_and_enable_with_mm():
    sim, _ = make_homed_sim()
    ask(sim, "1MM0")
    assert ask(sim, "1TS") == "1TS00003C"
    assert ask(sim, "1MM?") == "1MM3C"
    sim.handle_line("1PA10")
    assert te(sim) == "J"
    ask(sim, "1MM1")
    assert ask(sim, "1TS") == "1TS000034"


def test_stop_decelerates_at_ac_and_ends_ready_from_moving():
    sim, wall = make_homed_sim(acceleration_deg_s2=80.0, velocity_deg_s=20.0)
    ask(sim, "1PA100")
    wall.t += 2.0  # cruising at 20 deg/s
    before = sim.current_position()
    ask(sim, "1ST")
    wall.t += 1.0
    assert ask(sim, "1TS") == "1TS000033"
    # braking distance v^2 / (2 a) = 400 / 160 = 2.5 deg
    assert sim.current_position() == pytest.approx(before + 2.5)


def test_pa_while_moving_retargets_the_move():
    sim, wall = make_homed_sim()
    ask(sim, "1PA100")
    wall.t += 1.0
    ask(sim, "1PA-20")
    assert te(sim) == "@"
    wall.t += 100.0
    assert (ask(sim, "1TS"), ask(sim, "1TP")) == ("1TS000033", "1TP-20")


def test_reset_makes_the_controller_deaf_then_not_referenced():
    sim, wall = make_homed_sim(reset_time_s=2.0)
    ask(sim, "1RS")
    assert sim.handle_line("1TS") == []  # rebooting
    wall.t += 2.5
    assert ask(sim, "1TS") == "1TS00000A"
    sim.handle_line("1RS")
    assert te(sim) == "H"  # RS is refused in NOT REFERENCED (manual's RS error list)


def test_configuration_state_and_saving():
    sim, wall = make_sim(config_save_time_s=1.0)
    ask(sim, "1PW1")
    assert ask(sim, "1TS") == "1TS000014"
    ask(sim, "1ZX2")
    ask(sim, "1VA15")
    assert te(sim) == "@"
    ask(sim, "1PW0")
    assert sim.handle_line("1TS") == []  # saving to flash: no answer
    wall.t += 1.5
    assert ask(sim, "1TS") == "1TS00000C"
    assert ask(sim, "1VA?") == "1VA15"
    assert ask(sim, "1ZX?") == "1ZXURS100CC"  # the manual's ZX? example


def test_zt_lists_parameters_between_pw1_and_pw0():
    sim, _ = make_sim()
    lines = sim.handle_line("1ZT")
    assert lines[0] == "1PW1" and lines[-1] == "1PW0"
    assert "1AC320.000000" in lines  # the manual's ZT example line
    assert "1IDURS100CC" in lines


def test_pt_returns_the_move_time():
    sim, _ = make_homed_sim(velocity_deg_s=20.0, acceleration_deg_s2=80.0)
    # 10 deg: 0.25 s to 20 deg/s (2.5 deg), 5 deg cruise (0.25 s), 0.25 s to stop
    assert ask(sim, "1PT10") == "1PT0.75"


# -- motion profile ------------------------------------------------------------------------
def test_trapezoid_reaches_v_max_and_lasts_the_textbook_time():
    segments = trapezoid(0.0, 100.0, 20.0, 80.0)
    duration = segments[-1].t0 + segments[-1].duration
    assert duration == pytest.approx(100.0 / 20.0 + 20.0 / 80.0)
    assert segments[1].v0 == 20.0
    assert segments[-1].position(duration) == pytest.approx(100.0)


def test_short_move_is_a_triangle():
    segments = trapezoid(0.0, -1.0, 20.0, 80.0)
    duration = segments[-1].t0 + segments[-1].duration
    assert duration == pytest.approx(2.0 * math.sqrt(1.0 / 80.0))
    assert segments[-1].position(duration) == pytest.approx(-1.0)
    assert max(abs(s.v0) for s in segments) < 20.0


def test_profile_brakes_first_when_moving_away_from_the_target():
    segments = profile(0.0, 20.0, -10.0, 20.0, 80.0)
    assert segments[0].a == -80.0  # brake to rest first
    end = segments[-1].t0 + segments[-1].duration
    assert segments[-1].position(end) == pytest.approx(-10.0)


# -- faults --------------------------------------------------------------------------------
def test_stall_fault_gives_following_error_and_disable_from_moving():
    faults = FaultInjector()
    wall = StepClock()
    sim = Smc100Sim(clock=SimClock(clock=wall), faults=faults)
    home(sim, wall)
    faults.inject("stall:1")
    ask(sim, "1PA100")
    wall.t += 100.0
    assert ask(sim, "1TS") == "1TS00203D"
    assert ask(sim, "1TS") == "1TS00003D"  # TS read and cleared the error buffer
    assert 0.0 < sim.current_position() < 100.0
    ask(sim, "1MM1")
    assert ask(sim, "1TS") == "1TS000034"


def test_stall_hang_fault_stays_moving_until_stopped():
    faults = FaultInjector()
    faults.inject("stall-hang:1")
    wall = StepClock()
    sim = Smc100Sim(clock=SimClock(clock=wall), faults=faults)
    home(sim, wall)
    ask(sim, "1PA100")
    wall.t += 100.0
    assert ask(sim, "1TS") == "1TS000028"
    frozen = sim.current_position()
    wall.t += 100.0
    assert sim.current_position() == frozen
    ask(sim, "1ST")
    assert ask(sim, "1TS") == "1TS000033"


def test_instant_clock_completes_moves_at_once():
    sim = Smc100Sim(clock=SimClock(instant=True))
    ask(sim, "1OR")
    assert ask(sim, "1TS") == "1TS000032"
    ask(sim, "1PA-33.3")
    assert (ask(sim, "1TS"), ask(sim, "1TP")) == ("1TS000033", "1TP-33.3")


# -- over a real pty, byte for byte ---------------------------------------------------------
def _raw_port(path: str) -> serial.Serial:
    return serial.Serial(path, 57600, xonxoff=True, timeout=0.5)


def test_split_writes_empty_lines_and_xon_xoff_over_a_pty():
    with start_simulator("turntable", instant=True) as handle, _raw_port(handle.ports[0]) as port:
        port.write(b"\r\n\r\n1T")
        time.sleep(0.05)
        port.write(b"S\x11\r\n")
        assert port.read_until(b"\r\n") == b"1TS00000A\r\n"


def test_magaox_client_transcript():
    """Bytes the MagAOX smc100ccCtrl app sends (its Catch2 tests): ``1TS``, ``1OR``,
    ``1PA%f`` followed by ``1TE``."""
    with start_simulator("turntable", instant=True) as handle, _raw_port(handle.ports[0]) as port:
        for sent, expected in [
            (b"1TS\r\n", b"1TS00000A\r\n"),
            (b"1OR\r\n", None),
            (b"1TS\r\n", b"1TS000032\r\n"),
            (b"1PA2.000000\r\n", None),
            (b"1TE\r\n", b"1TE@\r\n"),
            (b"1TP\r\n", b"1TP2\r\n"),
            (b"1ST\r\n", None),
        ]:
            port.write(sent)
            if expected is not None:
                assert port.read_until(b"\r\n") == expected


def test_pysmc100_client_transcript():
    """Bytes pySMC100 (freespace/pySMC100) sends: queries with ``?`` as argument, and it
    rejects any reply byte outside 33..126 - so no blanks in these replies."""
    with start_simulator("turntable", instant=True) as handle, _raw_port(handle.ports[0]) as port:
        for sent, expected in [
            (b"1ID?\r\n", b"1IDURS100CC\r\n"),
            (b"1TS?\r\n", b"1TS00000A\r\n"),
            (b"1OR\r\n", None),
            (b"1TS?\r\n", b"1TS000032\r\n"),
            (b"1PA0\r\n", None),
            (b"1TS?\r\n", b"1TS000033\r\n"),
            (b"1PR1.5\r\n", None),
            (b"1TP?\r\n", b"1TP1.5\r\n"),
        ]:
            port.write(sent)
            if expected is not None:
                reply = port.read_until(b"\r\n")
                assert reply == expected
                assert all(33 <= b < 127 for b in reply[:-2])


# -- the drift fault -------------------------------------------------------------------------
def test_drift_moves_a_stage_at_rest_off_its_position_and_it_stays_ready():
    sim, wall = make_homed_sim()
    ask(sim, "1PA20")
    wall.t += 100.0
    assert ask(sim, "1TP") == "1TP20"
    sim.faults.inject("drift:1@1", offset_deg=0.25)
    assert ask(sim, "1TP") == "1TP20"  # the first command at rest is let through
    assert ask(sim, "1TP") == "1TP20.25"  # crept off before this one was answered
    assert ask(sim, "1TS") == "1TS000033" and ask(sim, "1TH") == "1TH20"  # READY, set-point kept
    ask(sim, "1PA20")  # the next move starts from where the stage really is
    wall.t += 100.0
    assert ask(sim, "1TP") == "1TP20"
