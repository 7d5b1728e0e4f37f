"""
The emulated EVI-D31's motion model: pan, tilt and zoom in continuous time (ROS-free).

Positions are in camera units (pan +-880 = +-100 deg, positive right; tilt
+-300 = +-25 deg, positive up; zoom 0 wide .. 3FFh tele) and speeds in units
per second. Velocity changes are instant (no ramps). Each axis follows a list
of legs (target, speed), so its position is exact at any instant, between
the emulator's video fields too. Bytes and replies are not this module's
business: see :mod:`~pattern_locator.visca.emulator_device`.
"""

import math
from typing import List, Tuple

from .protocol import PAN_LIMIT_UNITS, TILT_LIMIT_UNITS, ZOOM_TELE, ZOOM_WIDE

# Flags of the axes at an end of travel (pan-tilt mode answer, bits 3..0).
END_LEFT, END_RIGHT, END_UP, END_DOWN = 0x01, 0x02, 0x04, 0x08


class Axis:
    """One axis: a position following a list of legs (target, speed) in continuous time."""

    def __init__(self, position: float = 0.0) -> None:
        self._t0 = 0.0
        self._p0 = float(position)
        self._legs: List[Tuple[float, float]] = []
        # A running Drive: +1/-1 and its speed, so new limits can re-plan it.
        self.drive = 0
        self.drive_speed = 0.0

    def at(self, t: float) -> float:
        """Return the position at time ``t`` (not before the last change)."""
        p, start = self._p0, self._t0
        for target, speed in self._legs:
            duration = abs(target - p) / speed
            if t < start + duration:
                return p + math.copysign(speed * max(0.0, t - start), target - p)
            p, start = target, start + duration
        return p

    def end_time(self) -> float:
        """Return when the last leg ends."""
        p, end = self._p0, self._t0
        for target, speed in self._legs:
            end += abs(target - p) / speed
            p = target
        return end

    def moving(self, t: float) -> bool:
        """Return True while a leg runs at ``t``."""
        return t < self.end_time()

    def go(self, t: float, legs: List[Tuple[float, float]], drive: int = 0,
           drive_speed: float = 0.0) -> None:
        """From where the axis is at ``t``, follow ``legs`` (target, speed > 0) in turn."""
        self._p0 = self.at(t)
        self._t0 = t
        self._legs = [(float(target), float(speed)) for target, speed in legs if speed > 0.0]
        self.drive = drive
        self.drive_speed = drive_speed

    def jump(self, t: float, position: float) -> None:
        """Be at ``position`` from ``t`` on, still."""
        self._p0, self._t0, self._legs = float(position), t, []
        self.drive, self.drive_speed = 0, 0.0

    def stop(self, t: float) -> None:
        """Stay where the axis is at ``t``."""
        self.go(t, [])


class HeadMotion:
    """
    Pan, tilt and zoom of the head, with the LimitSet box (camera units, continuous time).

    Drive runs until stopped or the current limits (LimitSet corners, else
    travel); a LimitSet/Clear re-plans a running drive. Absolute targets are
    clamped into the LimitSet box, relative ones too. Each axis moves at
    its own speed.
    """

    def __init__(self) -> None:
        self.pan = Axis()
        self.tilt = Axis()
        self.zoom = Axis()
        self.pan_limits = [-PAN_LIMIT_UNITS, PAN_LIMIT_UNITS]
        self.tilt_limits = [-TILT_LIMIT_UNITS, TILT_LIMIT_UNITS]

    # State ----------------------------------------------------------------------------------

    def position(self, now: float) -> Tuple[float, float]:
        """Return (pan, tilt) in camera units, not rounded."""
        return self.pan.at(now), self.tilt.at(now)

    def zoom_at(self, now: float) -> float:
        """Return the zoom position in camera units, not rounded."""
        return self.zoom.at(now)

    def pan_tilt_moving(self, now: float) -> bool:
        """Return True while pan or tilt moves."""
        return self.pan.moving(now) or self.tilt.moving(now)

    def zoom_moving(self, now: float) -> bool:
        """Return True while the zoom moves."""
        return self.zoom.moving(now)

    def end_flags(self, now: float) -> int:
        """Return END_* flags of the axes at an end of travel (rounded units, as answered)."""
        pan, tilt = round(self.pan.at(now)), round(self.tilt.at(now))
        flags = 0
        if pan <= -PAN_LIMIT_UNITS:
            flags |= END_LEFT
        if pan >= PAN_LIMIT_UNITS:
            flags |= END_RIGHT
        if tilt >= TILT_LIMIT_UNITS:
            flags |= END_UP
        if tilt <= -TILT_LIMIT_UNITS:
            flags |= END_DOWN
        return flags

    # Motions --------------------------------------------------------------------------------

    def stop_all(self, now: float) -> None:
        """Stop every axis where it is."""
        for axis in (self.pan, self.tilt, self.zoom):
            axis.stop(now)

    def stop_pan_tilt(self, now: float) -> None:
        """Stop pan and tilt where they are."""
        self.pan.stop(now)
        self.tilt.stop(now)

    def drive(self, now: float, pan_direction: int, pan_speed: float, tilt_direction: int,
              tilt_speed: float) -> None:
        """Turn each axis at its speed (units/s) towards +1/-1, or stop it (0)."""
        self._drive(self.pan, self.pan_limits, now, pan_direction, pan_speed)
        self._drive(self.tilt, self.tilt_limits, now, tilt_direction, tilt_speed)

    def move_to(self, now: float, pan: int, tilt: int, pan_speed: float,
                tilt_speed: float) -> None:
        """Move to (pan, tilt) units clamped into the limits, each axis at its speed."""
        pan = min(max(pan, self.pan_limits[0]), self.pan_limits[1])
        tilt = min(max(tilt, self.tilt_limits[0]), self.tilt_limits[1])
        self.pan.go(now, [(pan, pan_speed)])
        self.tilt.go(now, [(tilt, tilt_speed)])

    def move_by(self, now: float, dpan: int, dtilt: int, pan_speed: float,
                tilt_speed: float) -> None:
        """Move by (dpan, dtilt) units from the rounded position now (clamped likewise)."""
        self.move_to(now, dpan + round(self.pan.at(now)), dtilt + round(self.tilt.at(now)),
                     pan_speed, tilt_speed)

    def sweep(self, now: float, duration: float, zoom: bool) -> None:
        """Sweep both axes through their ends back to 0 (and zoom wide) in ``duration``."""
        for axis, end in ((self.pan, PAN_LIMIT_UNITS), (self.tilt, TILT_LIMIT_UNITS)):
            start = axis.at(now)
            if duration <= 0.0:
                axis.jump(now, 0.0)
                continue
            speed = (abs(end - start) + 3.0 * end) / duration
            axis.go(now, [(end, speed), (-end, speed), (0.0, speed)])
        if zoom:
            start = self.zoom.at(now)
            if duration <= 0.0 or start == 0.0:
                self.zoom.jump(now, 0.0)
            else:
                self.zoom.go(now, [(0.0, start / duration)])

    def zoom_run(self, now: float, direction: int, units_s: float) -> None:
        """Zoom towards tele (+1) or wide (-1) at ``units_s`` until the end, or stop (0)."""
        if direction == 0:
            self.zoom.stop(now)
        else:
            self.zoom.go(now, [(ZOOM_TELE if direction > 0 else ZOOM_WIDE, units_s)])

    def zoom_to(self, now: float, position: int, units_s: float) -> None:
        """Zoom to ``position`` units at ``units_s``."""
        self.zoom.go(now, [(position, units_s)])

    # Limits ---------------------------------------------------------------------------------

    def clear_limits(self) -> None:
        """Back to the full travel (power-up)."""
        self.pan_limits = [-PAN_LIMIT_UNITS, PAN_LIMIT_UNITS]
        self.tilt_limits = [-TILT_LIMIT_UNITS, TILT_LIMIT_UNITS]

    def limit_set_allowed(self, up_right: bool, pan: int, tilt: int) -> bool:
        """Return False for a corner that would cross the other corner."""
        if up_right:
            return pan >= self.pan_limits[0] and tilt >= self.tilt_limits[0]
        return pan <= self.pan_limits[1] and tilt <= self.tilt_limits[1]

    def set_limit(self, now: float, up_right: bool, pan: int, tilt: int) -> None:
        """Set the up-right or down-left corner; a running drive stops there."""
        self.pan_limits[1 if up_right else 0] = pan
        self.tilt_limits[1 if up_right else 0] = tilt
        self._replan_drives(now)

    def clear_limit(self, now: float, up_right: bool) -> None:
        """Clear one corner back to the end of travel; a running drive goes on to it."""
        if up_right:
            self.pan_limits[1], self.tilt_limits[1] = PAN_LIMIT_UNITS, TILT_LIMIT_UNITS
        else:
            self.pan_limits[0], self.tilt_limits[0] = -PAN_LIMIT_UNITS, -TILT_LIMIT_UNITS
        self._replan_drives(now)

    @staticmethod
    def _drive(axis: Axis, limits: List[int], now: float, direction: int,
               speed: float) -> None:
        position = axis.at(now)
        if direction > 0:
            axis.go(now, [(max(limits[1], position), speed)], direction, speed)
        elif direction < 0:
            axis.go(now, [(min(limits[0], position), speed)], direction, speed)
        else:
            axis.stop(now)

    def _replan_drives(self, now: float) -> None:
        for axis, limits in ((self.pan, self.pan_limits), (self.tilt, self.tilt_limits)):
            if axis.drive:
                self._drive(axis, limits, now, axis.drive, axis.drive_speed)
