"""The wire contract (keys, messages) and Zenoh session set-up shared by every process."""
from .keys import TOPICS, Keys, check_swarm, message_for_key
from .messages import (ALL_MESSAGES, Clock, CmdVel, Complex, Demo, LiveCmd, Message,
                       MocapPose, Pose, Remove, Sense, Spawn, Status, Task, Truth, TwinCmd,
                       WireError, WorldInfo, decode, encode)

__all__ = [
    "TOPICS", "Keys", "check_swarm", "message_for_key", "ALL_MESSAGES", "Clock", "CmdVel",
    "Complex", "Demo", "LiveCmd", "Message", "MocapPose", "Pose", "Remove", "Sense", "Spawn",
    "Status", "Task", "Truth", "TwinCmd", "WireError", "WorldInfo", "decode", "encode",
]
