"""What the deployment cycle asks its process to do: typed actions, one class per kind.

:meth:`coordinator.deployer.Deployer.step` returns a list of these, in order; the
coordinator process (coordinator/node.py) turns each into a message on the bus, and the
in-process loop (swarmcover/simloop.py) applies each directly. Both dispatch with ``match``
on the class, so a new kind is a new class, never a new string.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Union

from swarmcover.bus.messages import Complex, Remove, Spawn, Task


@dataclass(frozen=True)
class SendTask:
    """Send ``task`` to robot ``robot`` (its Task key)."""
    robot: int
    task: Task


@dataclass(frozen=True)
class SpawnRobot:
    """Ask for a new robot at a source (the world adds its body, ``run`` its agent)."""
    spawn: Spawn


@dataclass(frozen=True)
class RemoveRobot:
    """Take a robot's body out of the world (it failed or was sent away)."""
    remove: Remove


@dataclass(frozen=True)
class PublishComplex:
    """Publish the cycle's complex, fence and certificate state."""
    complex: Complex


@dataclass(frozen=True)
class RequestStatus:
    """Ask every robot for a Status now (a lockstep world may sense idle robots only every
    few seconds: world/wake.py); the barrier's ack carries it (CoordAck.report)."""


@dataclass(frozen=True)
class Done:
    """The run is over: ``certified`` or stopped (Deployer.stop_reason says why)."""
    certified: bool


Action = Union[SendTask, SpawnRobot, RemoveRobot, PublishComplex, RequestStatus, Done]


class Outbox:
    """The actions of one deployer step, in order, and the ids of the tasks they send.

    Task ids are ``epoch * 1_000_000 + n`` with n counting up from 1 (a restarted
    coordinator takes a new epoch, or raises n past the ids its agents report)."""

    def __init__(self, epoch: int = 0):
        self.epoch = epoch
        self.next_task = 1
        self.actions: list[Action] = []

    def send(self, rid: int, task: Task) -> int:
        """Number ``task`` and address it to robot ``rid``; returns its task id."""
        task.task_id = self.epoch * 1_000_000 + self.next_task
        self.next_task += 1
        task.robot = rid
        task.epoch = self.epoch
        self.actions.append(SendTask(rid, task))
        return task.task_id

    def spawn(self, spawn: Spawn) -> int:
        """Ask for the robot of ``spawn``; returns its id."""
        self.actions.append(SpawnRobot(spawn))
        return spawn.robot

    def add(self, action: Action) -> None:
        self.actions.append(action)

    def request_status(self) -> None:
        """Ask every robot for a fresh Status (once per step)."""
        if not any(isinstance(a, RequestStatus) for a in self.actions):
            self.actions.append(RequestStatus())


__all__ = ["Action", "Done", "Outbox", "PublishComplex", "RemoveRobot", "RequestStatus",
           "SendTask", "SpawnRobot"]
