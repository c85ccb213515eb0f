"""Who sent a message, without ``--secure``: the coordinator's signed samples.

Zenoh carries no proof of a sample's sender: ``sample.source_info`` (the publishing
entity's session id ``zid`` and a sequence number) is whatever the publisher wrote, and any
session may write another's. Two checks are layered here, for what the coordinator sends
(``coord/complex`` and ``world/spawn``):

* **Session id.** The coordinator puts with ``source_info`` = its publisher's global id and
  prints its session id on its READY line; ``swarmcover run`` (which started it and reads
  that line from its own log) accepts a Complex or Spawn only from that zid. This stops a
  stray or careless publisher, not a deliberate forger (the zid is visible on the network).
* **A run key.** ``run`` makes a random key per run and gives it to the coordinator it
  starts in the environment (``SWARMCOVER_RUN_KEY``, never on a command line or the
  network); the coordinator attaches HMAC-SHA256(key, key expression + payload) to each of
  those samples and ``run`` checks it. Without the key a forger cannot make a sample
  ``run`` accepts; a replay of a genuine sample is refused by the checks in ``run`` (its
  epoch and cycle must move forward).

Everything else on the bus (Sense, CmdVel, Status, Task, Clock, Remove, Truth) is only
authenticated by the ``--secure`` profile (TLS, per-process credentials, ACLs).
"""
from __future__ import annotations

import hashlib
import hmac
import os
import secrets

import zenoh

KEY_ENV = "SWARMCOVER_RUN_KEY"
MAC_LEN = 32


def new_key() -> str:
    """A fresh run key (hex)."""
    return secrets.token_hex(32)


def key_from_env() -> bytes | None:
    k = os.environ.get(KEY_ENV, "").strip()
    if not k:
        return None
    try:
        return bytes.fromhex(k)
    except ValueError:
        return None


def mac(key: bytes, key_expr: str, payload: bytes) -> bytes:
    """HMAC-SHA256 over the key expression and the payload (a sample moved to another key
    does not verify)."""
    h = hmac.new(key, key_expr.encode() + b"\0", hashlib.sha256)
    h.update(payload)
    return h.digest()


def verify(key: bytes, key_expr: str, payload: bytes, attachment: bytes | None) -> bool:
    return attachment is not None and len(attachment) == MAC_LEN and \
        hmac.compare_digest(mac(key, key_expr, payload), attachment)


class SignedPublisher:
    """Puts on one declared publisher with ``source_info`` (this session's entity id and a
    sequence number) and, when a run key is set, the HMAC as the sample's attachment."""

    def __init__(self, publisher: zenoh.Publisher, key: bytes | None):
        self.pub = publisher
        self.key = key
        self.key_expr = str(publisher.key_expr)
        self.sn = 0
        try:
            self._id = publisher.id
        except Exception:  # an older zenoh without entity ids: no source_info
            self._id = None

    def put(self, payload: bytes) -> None:
        self.sn += 1
        kw = {}
        if self._id is not None:
            kw["source_info"] = zenoh.SourceInfo(self._id, self.sn)
        if self.key is not None:
            kw["attachment"] = mac(self.key, self.key_expr, payload)
        self.pub.put(payload, **kw)

    def undeclare(self) -> None:
        self.pub.undeclare()


def sample_origin(sample: zenoh.Sample) -> tuple[str | None, bytes | None]:
    """(source zid as text or None, attachment bytes or None) of a sample."""
    zid = None
    try:
        si = sample.source_info
        if si is not None:
            zid = str(si.source_id.zid)
    except Exception:
        zid = None
    att = sample.attachment
    return zid, (att.to_bytes() if att is not None else None)


class CoordinatorGate:
    """For viewers: let a Complex through only from the coordinator.

    With the run key (``run --view`` gives it to the viewer it starts) a sample needs a valid
    signature. Without it (a viewer started by hand, on another host): trust on first use
    per coordinator life, i.e. the first source zid seen while a coordinator liveliness token
    (``alive/coordinator/*``) is present is pinned until the tokens go away; samples with no
    ``source_info``, from another zid, or while no coordinator is alive are dropped and
    counted in ``refused``. ``wrap(callback)`` gives a Zenoh callback that filters.
    """

    def __init__(self, key: bytes | None = None):
        self.key = key if key is not None else key_from_env()
        self.zid: str | None = None
        self.tokens: set[str] = set()
        self.refused = 0
        self._sub = None

    def attach(self, session: zenoh.Session, prefix: str,
               timeout: float = 2.0) -> "CoordinatorGate":
        """Watch the coordinator's tokens; the ones present now are fetched before this
        returns, so a Complex that arrives right after is not refused for want of them."""
        key = f"{prefix}/alive/coordinator/*"
        self._sub = session.liveliness().declare_subscriber(key, self._on_token, history=True)
        try:
            for reply in session.liveliness().get(key, timeout=timeout):
                if reply.ok is not None:
                    self.tokens.add(str(reply.ok.key_expr))
        except Exception:  # no router yet: the subscriber's history fills them in later
            pass
        return self

    def _on_token(self, sample: zenoh.Sample) -> None:
        k = str(sample.key_expr)
        if sample.kind == zenoh.SampleKind.PUT:
            self.tokens.add(k)
        else:
            self.tokens.discard(k)
            if not self.tokens:
                self.zid = None

    def accept(self, sample: zenoh.Sample) -> bool:
        zid, att = sample_origin(sample)
        if self.key is not None:
            ok = verify(self.key, str(sample.key_expr), sample.payload.to_bytes(), att)
        elif zid is None or not self.tokens:
            ok = False
        else:
            if self.zid is None:
                self.zid = zid
            ok = zid == self.zid
        if not ok:
            self.refused += 1
        return ok

    def wrap(self, callback):
        def cb(sample):
            if self.accept(sample):
                callback(sample)
        return cb

    def undeclare(self) -> None:
        if self._sub is not None:
            self._sub.undeclare()
            self._sub = None
