"""Maintenance windows (pure): is a robot's window open at a given moment, and when does it open or close.

fleet.yaml's ``rollout.windows`` (:class:`~robocore.config.fleet.Window`) each select robots (by name, by labels,
or every robot) and open on some week days from ``from`` to ``to`` in a time zone (an IANA name, read with
:mod:`zoneinfo`, so daylight saving time is the zone's). A window whose ``to`` is not after its ``from`` ends the
next day (``22:00``-``06:00``); it belongs to the day it opens on. A robot that no window selects may be updated at
any time; a robot that some select, only inside one of them. Every moment is compared in UTC, so two windows in
two zones, or a window across a change of the clocks, compare as instants.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import date, datetime, time, timedelta, timezone
from zoneinfo import ZoneInfo

from robocore.config.fleet import DAYS, Fleet, FleetRobot, Window

#: How many days ahead the next opening is looked for (a window opens at least once a week).
LOOKAHEAD_DAYS = 8


@dataclass(frozen=True)
class WindowState:
    """A robot's windows at one moment: open or not, and when that changes (UTC; None when it never does)."""

    open: bool
    change: datetime | None
    zone: str

    @property
    def reason(self) -> str:
        """In words, in the window's own time zone: ``window opens at 2026-12-08 02:00 Europe/Berlin``."""
        verb = "closes" if self.open else "opens"
        if self.change is None:
            return f"window {verb} never"
        local = self.change.astimezone(ZoneInfo(self.zone))
        return f"window {verb} at {local:%Y-%m-%d %H:%M} {self.zone}"


def selects(window: Window, robot: FleetRobot) -> bool:
    """Whether ``window`` applies to ``robot`` (by name, by all its labels, or every robot without a selector)."""
    if window.robots is not None:
        return robot.name in window.robots
    if window.labels is not None:
        return window.labels.items() <= robot.labels.items()
    return True


def windows_of(fleet: Fleet, robot: str) -> list[Window]:
    """The windows of ``fleet`` that apply to ``robot``, in file order."""
    chosen = fleet.robot(robot)
    return [window for window in fleet.rollout.windows if selects(window, chosen)]


def _clock(text: str) -> tuple[time, int]:
    """``HH:MM`` as a time of day and a day offset (``24:00`` is 00:00 of the next day)."""
    hours, minutes = (int(part) for part in text.split(":"))
    return (time(0, 0), 1) if hours == 24 else (time(hours, minutes), 0)


def openings(window: Window, around: datetime) -> list[tuple[datetime, datetime]]:
    """``window``'s openings (start, end, in UTC) that start from the day before ``around`` to
    :data:`LOOKAHEAD_DAYS` after it, in order."""
    zone = ZoneInfo(window.timezone)
    today = around.astimezone(zone).date()
    start, _ = _clock(window.start)
    end, end_offset = _clock(window.end)
    spans = []
    for offset in range(-1, LOOKAHEAD_DAYS):
        day: date = today + timedelta(days=offset)
        if DAYS[day.weekday()] not in window.days:
            continue
        opens = datetime.combine(day, start, tzinfo=zone)
        closes = datetime.combine(day + timedelta(days=end_offset), end, tzinfo=zone)
        if closes <= opens:
            closes = datetime.combine(day + timedelta(days=1), end, tzinfo=zone)
        spans.append((opens.astimezone(timezone.utc), closes.astimezone(timezone.utc)))
    return spans


def window_state(windows: Sequence[Window], now: datetime) -> WindowState | None:
    """Whether a robot with ``windows`` may be updated at ``now`` (an aware datetime): None when no window applies
    (it may, always); else open (and when the last open window closes) or closed (and when the first opens)."""
    if not windows:
        return None
    now = now.astimezone(timezone.utc)
    inside = [(end, window.timezone) for window in windows for begin, end in openings(window, now)
              if begin <= now < end]
    if inside:
        end, zone = max(inside)
        return WindowState(open=True, change=end, zone=zone)
    ahead = [(begin, window.timezone) for window in windows for begin, _ in openings(window, now) if begin > now]
    if not ahead:
        return WindowState(open=False, change=None, zone=windows[0].timezone)
    begin, zone = min(ahead)
    return WindowState(open=False, change=begin, zone=zone)
