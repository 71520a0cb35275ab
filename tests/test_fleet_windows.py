"""Maintenance windows and rollout.timeouts.busy: fleet.yaml's keys, their file:line: key problems, and the pure
planning (is a robot's window open, when does it open or close) at fixed moments, daylight saving time included."""

from __future__ import annotations

from datetime import datetime, timezone
from zoneinfo import ZoneInfo

import jsonschema
import pytest
import yaml

from robocore.config.fleet import DAYS, Fleet, Window, parse_fleet_text
from robocore.config.loader import parse_robot_text
from robocore.config.model import Robot
from robocore.config.schema import fleet_schema
from robocore.errors import ConfigError
from robocore.plan.fleet_lock import hold_reason
from robocore.plan.fleet_windows import window_state, windows_of

ROBOT = """\
ros_distro: jazzy
registry: 10.0.0.2:5000
hosts:
  - {name: main, ip: 192.168.1.10, user: me}
components:
  - {name: talker, folder: components/talker, runs_on: main}
"""
FLEET = """\
manager: {ip: 10.0.0.2}
robots:
  - {name: r1, labels: {site: lab}, hosts: {main: {ip: 10.0.1.5}}}
  - {name: r2, labels: {site: field}, hosts: {main: {ip: 10.0.2.5}}}
  - {name: r3, hosts: {main: {ip: 10.0.3.5}}}
rollout:
  timeouts: {robot: 60, wave: 300, busy: 900}
  windows:
    - {labels: {site: field}, days: [mon, tue, wed, thu, fri], from: "22:00", to: "06:00", timezone: Europe/Berlin}
    - {robots: [r3], from: "12:00", to: "13:00"}
"""
BERLIN = ZoneInfo("Europe/Berlin")


@pytest.fixture(scope="module")
def robot() -> Robot:
    return parse_robot_text(ROBOT)


@pytest.fixture(scope="module")
def fleet(robot: Robot) -> Fleet:
    return parse_fleet_text(FLEET, robot)


def refusal(text: str, robot: Robot) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse_fleet_text(text, robot)
    return caught.value.lines()


def at(text: str, zone: ZoneInfo = BERLIN) -> datetime:
    """A fixed moment: ``2026-12-07 23:30`` in ``zone``."""
    return datetime.strptime(text, "%Y-%m-%d %H:%M").replace(tzinfo=zone)


def test_windows_and_the_busy_timeout_load(fleet: Fleet, robot: Robot) -> None:
    assert fleet.rollout.timeouts.busy == 900
    field, noon = fleet.rollout.windows
    assert (field.labels, field.days, field.start, field.end, field.timezone) == \
        ({"site": "field"}, ["mon", "tue", "wed", "thu", "fri"], "22:00", "06:00", "Europe/Berlin")
    assert (noon.robots, noon.days, noon.timezone) == (["r3"], list(DAYS), "UTC")  # every day, UTC by default
    plain = parse_fleet_text("manager: {ip: 10.0.0.2}\nrobots:\n  - {name: a, hosts: {main: {ip: 10.0.0.9}}}\n", robot)
    assert plain.rollout.windows == [] and plain.rollout.timeouts.busy == 600


def test_bad_windows_are_one_line_each_naming_file_line_and_key(robot: Robot) -> None:
    text = FLEET.replace("days: [mon, tue, wed, thu, fri]", "days: [mon, someday]").replace(
        "timezone: Europe/Berlin", "timezone: Mars/Olympus").replace('to: "13:00"', 'to: "12:00"')
    text = text.replace("robots: [r3]", "robots: [r9]").replace("busy: 900", "busy: 0")
    text += '    - {robots: [r1], labels: {site: lab}, from: "25:00", to: "1:00", colour: red}\n'
    lines = refusal(text, robot)
    assert lines == [
        "fleet.yaml:7: rollout.timeouts.busy: 0 is out of range (must be at least 1)",
        "fleet.yaml:9: rollout.windows[0].days[1]: 'someday' is not one of: mon, tue, wed, thu, fri, sat, sun",
        "fleet.yaml:9: rollout.windows[0].timezone: 'Mars/Olympus' is not a time zone this machine knows (an IANA "
        "name such as Europe/Berlin, or UTC)",
        "fleet.yaml:10: rollout.windows[1]: from and to are both 12:00: an empty window (for all day: from 00:00 to "
        "24:00)",
        "fleet.yaml:11: rollout.windows[2].from: '25:00' is not a valid value here (expected a time of day HH:MM, "
        "00:00 to 23:59)",
        "fleet.yaml:11: rollout.windows[2].to: '1:00' is not a valid value here (expected a time of day HH:MM, 00:00 "
        "to 24:00)",
        "fleet.yaml:11: rollout.windows[2].colour: unknown key 'colour' (allowed: days, from, labels, robots, "
        "timezone, to)",
    ], lines
    # a window's robots name robots of the fleet
    assert refusal(FLEET.replace("robots: [r3]", "robots: [r9]"), robot) == \
        ["fleet.yaml:10: rollout.windows[1].robots[0]: unknown robot 'r9' (known: r1, r2, r3)"]


def test_a_window_takes_one_selector(robot: Robot) -> None:
    text = FLEET + '    - {robots: [r1], labels: {site: lab}, from: "01:00", to: "02:00"}\n'
    assert refusal(text, robot) == ["fleet.yaml:11: rollout.windows[2]: a window takes one selector, not robots and "
                                    "labels"]


def test_the_schema_has_the_windows_as_the_file_writes_them(robot: Robot) -> None:
    doc = yaml.safe_load(FLEET)
    assert not list(jsonschema.Draft202012Validator(fleet_schema()).iter_errors(doc))
    doc["rollout"]["windows"][0]["from"] = "7am"
    assert list(jsonschema.Draft202012Validator(fleet_schema()).iter_errors(doc))


def test_which_windows_apply_to_a_robot(fleet: Fleet) -> None:
    assert windows_of(fleet, "r1") == []  # no window selects it: updated at any time
    assert [w.labels for w in windows_of(fleet, "r2")] == [{"site": "field"}]
    assert [w.robots for w in windows_of(fleet, "r3")] == [["r3"]]
    assert window_state(windows_of(fleet, "r1"), at("2026-12-07 15:00")) is None


def test_an_overnight_window_on_week_days(fleet: Fleet) -> None:
    windows = windows_of(fleet, "r2")
    monday_night = window_state(windows, at("2026-12-07 23:30"))  # a Monday
    assert monday_night is not None and monday_night.open
    assert monday_night.reason == "window closes at 2026-12-08 06:00 Europe/Berlin"  # the next morning
    tuesday_morning = window_state(windows, at("2026-12-08 05:59"))  # the Monday window, still open
    assert tuesday_morning is not None and tuesday_morning.open
    afternoon = window_state(windows, at("2026-12-08 15:00"))
    assert afternoon is not None and not afternoon.open
    assert afternoon.reason == "window opens at 2026-12-08 22:00 Europe/Berlin"
    saturday = window_state(windows, at("2026-12-12 23:30"))  # opens on week days only: next on Monday night
    assert saturday is not None and not saturday.open
    assert saturday.reason == "window opens at 2026-12-14 22:00 Europe/Berlin"
    # Friday's window ends on Saturday morning: it belongs to the day it opens on
    friday_night = window_state(windows, at("2026-12-12 05:00"))
    assert friday_night is not None and friday_night.open


def test_moments_compare_as_instants_across_zones(fleet: Fleet) -> None:
    windows = windows_of(fleet, "r2")
    utc = window_state(windows, datetime(2026, 12, 7, 21, 30, tzinfo=timezone.utc))  # 22:30 in Berlin (CET)
    assert utc is not None and utc.open
    noon = windows_of(fleet, "r3")  # 12:00-13:00 UTC: 13:30 in Berlin is 12:30 UTC
    state = window_state(noon, at("2026-12-07 13:30"))
    assert state is not None and state.open and state.reason == "window closes at 2026-12-07 13:00 UTC"
    state = window_state(noon, at("2026-12-07 14:00"))  # 13:00 UTC: closed (the end is not inside)
    assert state is not None and not state.open and state.reason == "window opens at 2026-12-08 12:00 UTC"


def test_daylight_saving_time_is_the_zones() -> None:
    window = Window.model_validate({"from": "01:00", "to": "04:00", "timezone": "Europe/Berlin"})
    # 2026-03-29: clocks go from 02:00 to 03:00 in Berlin; the window is 01:00-04:00 local, two hours long
    state = window_state([window], datetime(2026, 3, 29, 1, 30, tzinfo=timezone.utc))  # 03:30 CEST
    assert state is not None and state.open and state.reason == "window closes at 2026-03-29 04:00 Europe/Berlin"
    assert state.change == datetime(2026, 3, 29, 2, 0, tzinfo=timezone.utc)
    state = window_state([window], datetime(2026, 3, 29, 2, 0, tzinfo=timezone.utc))  # 04:00 CEST: closed
    assert state is not None and not state.open
    assert state.change == datetime(2026, 3, 29, 23, 0, tzinfo=timezone.utc)  # 01:00 CEST the next day


def test_all_day_and_several_windows() -> None:
    all_day = Window.model_validate({"days": ["sun"], "from": "00:00", "to": "24:00"})
    night = Window.model_validate({"from": "02:00", "to": "03:00"})
    sunday = datetime(2026, 12, 13, 18, 0, tzinfo=timezone.utc)
    state = window_state([night, all_day], sunday)
    assert state is not None and state.open and state.reason == "window closes at 2026-12-14 00:00 UTC"
    monday = datetime(2026, 12, 14, 1, 0, tzinfo=timezone.utc)
    state = window_state([night, all_day], monday)  # the earliest opening of any window
    assert state is not None and not state.open and state.reason == "window opens at 2026-12-14 02:00 UTC"


def test_why_a_robot_is_held_back(fleet: Fleet) -> None:
    closed = window_state(windows_of(fleet, "r2"), at("2026-12-08 15:00"))
    opened = window_state(windows_of(fleet, "r2"), at("2026-12-07 23:00"))
    assert hold_reason(closed, False) == \
        "outside its maintenance window: window opens at 2026-12-08 22:00 Europe/Berlin"
    assert hold_reason(opened, False) == "" and hold_reason(None, False) == ""
    assert hold_reason(opened, True) == "holds its update lock (/robocore/update_lock)"
    assert hold_reason(None, None, "boom") == "cannot read its update lock (boom)"
