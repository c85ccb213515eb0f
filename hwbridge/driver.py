"""Robot-side command expiry: what a live robot's driver must do (pure; time is passed in).

Every LiveCmd carries ``ttl``: how long the robot may execute it, counted from its receipt
on the robot's own clock. The driver keeps the deadline ``receipt + ttl`` of the last
command and, from a loop or timer of its own (never from message arrival), commands zero
once the deadline passes and no newer command came. Then the robot stops whoever failed:
the bridge (killed, frozen), the router, the network or the agent.

Why a relative ttl and not an absolute deadline: the bridge and the robot are different
hosts whose clocks are not synchronised; an absolute deadline would be off by their skew
(seconds or more without NTP/PTP), while a duration measured from receipt needs no common
clock. The price: a packet delayed in the network is still executed for ``ttl`` after it
arrives, so the bound is "ttl after the last command that got through", which is what
stops a robot whose command stream died.

A command without a ttl (``ttl = 0``: a sender that predates the field, or a ROS 2 Twist,
which has no such field) gets the driver's own ``timeout_s``; any ttl is capped at
``timeout_s``, so no sender can make the robot drive blind for longer than its driver
allows.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

DEFAULT_TIMEOUT_S = 0.5   # as diff_drive_controller's cmd_vel_timeout default


@dataclass
class CommandExpiry:
    """The expiry watchdog of one robot driver.

    ``on_command`` at each received command; ``expired`` on every tick of the driver's own
    loop: True once when a non-zero command's deadline has passed (the driver then commands
    zero); ``stops`` counts those stops.
    """
    timeout_s: float = DEFAULT_TIMEOUT_S
    deadline: float = -math.inf
    moving: bool = False
    stops: int = 0
    last_ttl: float = 0.0

    def __post_init__(self):
        if not (isinstance(self.timeout_s, (int, float)) and math.isfinite(self.timeout_s)
                and self.timeout_s > 0):
            raise ValueError(f"command timeout: must be a finite number of seconds > 0, "
                             f"got {self.timeout_s!r}")

    def effective_ttl(self, ttl: float) -> float:
        """The ttl the driver applies: the sender's, capped at ``timeout_s``; ``timeout_s``
        when the sender gave none (0, negative or not finite)."""
        if not (isinstance(ttl, (int, float)) and math.isfinite(ttl)) or ttl <= 0:
            return float(self.timeout_s)
        return min(float(ttl), float(self.timeout_s))

    def on_command(self, now: float, v: float, omega: float, ttl: float = 0.0) -> float:
        """A command (m/s, rad/s) received at ``now`` (robot clock, s); returns its deadline."""
        self.last_ttl = self.effective_ttl(ttl)
        self.deadline = now + self.last_ttl
        self.moving = v != 0.0 or omega != 0.0
        return self.deadline

    def expired(self, now: float) -> bool:
        """True (once) if a non-zero command is in force and its deadline has passed."""
        if self.moving and now >= self.deadline:
            self.moving = False
            self.stops += 1
            return True
        return False
