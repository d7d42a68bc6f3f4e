"""Fault names, their text form, and the injector's counting."""

from __future__ import annotations

import pytest

from drivers.errors import DeviceInputError
from drivers.sim.faults import (
    CAMERA_FAULT_NAMES,
    FAULT_NAMES,
    SOLAR_FAULTS,
    TURNTABLE_FAULTS,
    FaultInjector,
    FaultSpec,
    parse_fault,
)

pytestmark = pytest.mark.timeout(10)


def test_every_required_fault_has_a_name():
    for name in ("no-reply", "garbled", "truncated", "stall", "disconnect", "lamp-fault"):
        assert name in FAULT_NAMES
    assert set(TURNTABLE_FAULTS) | set(SOLAR_FAULTS) | set(CAMERA_FAULT_NAMES) == set(FAULT_NAMES)


@pytest.mark.parametrize(
    ("text", "name", "count", "skip"),
    [
        ("no-reply", "no-reply", None, 0),
        ("garbled:1", "garbled", 1, 0),
        ("truncated:2@3", "truncated", 2, 3),
        ("stall@1", "stall", None, 1),
        (" lamp-fault ", "lamp-fault", None, 0),
    ],
)
def test_parse_fault_reads_name_count_and_skip(text, name, count, skip):
    spec = parse_fault(text)
    assert (spec.name, spec.count, spec.skip) == (name, count, skip)
    assert parse_fault(str(spec)) == spec


def test_unknown_fault_names_the_field_and_the_known_faults():
    with pytest.raises(DeviceInputError, match=r"fault: unknown fault 'smoke'.*no-reply"):
        parse_fault("smoke")


def test_fault_not_applicable_to_the_device_is_refused():
    with pytest.raises(DeviceInputError, match=r"does not apply here; allowed: .*stall"):
        parse_fault("lamp-fault", TURNTABLE_FAULTS)


@pytest.mark.parametrize("text", ["", "garbled:", "garbled:0", "garbled:x", "GARBLED", "a b"])
def test_malformed_fault_text_is_refused(text):
    with pytest.raises(DeviceInputError, match="fault"):
        parse_fault(text)


def test_counted_fault_fires_count_times_after_skipping():
    injector = FaultInjector([FaultSpec("garbled", count=2, skip=1)])
    fired = [injector.fire("garbled") is not None for _ in range(5)]
    assert fired == [False, True, True, False, False]
    assert not injector.is_armed("garbled")
    assert injector.fired == ["garbled", "garbled"]


def test_persistent_fault_fires_until_cleared():
    injector = FaultInjector()
    injector.inject("no-reply")
    assert all(injector.fire("no-reply") for _ in range(10))
    injector.clear("no-reply")
    assert injector.fire("no-reply") is None


def test_fire_counts_only_faults_of_that_name():
    injector = FaultInjector([FaultSpec("stall", count=1), FaultSpec("garbled", count=1)])
    assert injector.fire("truncated") is None
    assert injector.fire("stall") is not None
    assert [spec.name for spec in injector.armed()] == ["garbled"]


def test_inject_keeps_parameters():
    injector = FaultInjector()
    spec = injector.inject("disconnect:1", downtime_s=0.2)
    assert spec.params == {"downtime_s": 0.2}
    fired = injector.fire("disconnect")
    assert fired is not None and fired.params["downtime_s"] == 0.2


def test_a_rig_fault_names_its_device_and_a_fault_that_device_can_have():
    from drivers.sim.faults import parse_rig_fault

    device, spec = parse_rig_fault("solar-simulator:lamp-fault:1@6")
    assert (device, spec.name, spec.count, spec.skip) == ("solar-simulator", "lamp-fault", 1, 6)
    assert parse_rig_fault("camera:drop")[0] == "camera"
    for text, words in [("lamp-fault", "expected DEVICE:"), ("oven:stall", "expected DEVICE:"),
                        ("turntable:lamp-fault", "turntable: fault 'lamp-fault' does not apply"),
                        ("camera:smoke", "camera: unknown fault 'smoke'")]:
        with pytest.raises(DeviceInputError, match=words):
            parse_rig_fault(text)
