"""Secure profile (``--secure DIR``) -> Zenoh config inserts: mutual TLS, user/password, ACL.

A profile directory is made by ``swarmcover secure init DIR`` (see swarmcover/secure.py and
docs/lab-network.md). Layout (all PEM files; keys are PKCS#8, mode 0600)::

    DIR/ca/ca.pem                       the CA every link is verified against
    DIR/ca/ca.key                       CA key (only on the machine that issues certificates)
    DIR/router/router.pem, router.key   the router's TLS certificate (SANs: --host names/IPs)
    DIR/router/passwords.txt            user:password dictionary (router only)
    DIR/router/acl.json5                the ``access_control`` section (router only)
    DIR/ids/<name>/cert.pem, key.pem    a client's TLS certificate, CN = <name>
    DIR/ids/<name>/password             that client's password; the username is <name>

A process's identity is ``<role>`` or, for agents, ``agent-<id>``. The role comes from
``--role`` or, when absent, from the command (``swarmcover world`` -> world, ``agent`` ->
agent, ``coordinator``, ``hwbridge``, ``fake-robot`` -> live, ``router`` -> router, every
other command -> viewer); an agent's id comes from its ``--id``. With a profile, every
``tcp/`` endpoint is upgraded to ``tls/`` on the same host and port; other link kinds are
refused (they would bypass TLS).

No Zenoh calls here: :func:`config_inserts` returns ``(path, json5)`` pairs that
bus.session.make_config inserts.
"""
from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from pathlib import Path

#: Roles a profile knows. ``live`` is the live-robot side (robot driver / mocap source,
#: e.g. ``swarmcover fake-robot``); ``router`` is the hub itself.
ROLES = ("world", "coordinator", "agent", "hwbridge", "viewer", "live", "router")

#: Role inferred from a command's argparse ``prog`` (its last word); default ``viewer``.
ROLE_BY_COMMAND = {
    "world": "world", "coordinator": "coordinator", "agent": "agent",
    "hwbridge": "hwbridge", "fake-robot": "live", "router": "router",
}

ENV_SECURE = "SWARMCOVER_SECURE"
_NAME_RE = re.compile(r"^[a-z][a-z0-9\-]{0,62}$")


class SecurityError(ValueError):
    """A profile file is missing or unusable; the message names the file or flag."""


def infer_role(prog: str | None) -> str:
    """The role of a command from its argparse prog, e.g. 'swarmcover agent' -> 'agent'."""
    words = (prog or "").split()
    for w in reversed(words):
        if w in ROLE_BY_COMMAND:
            return ROLE_BY_COMMAND[w]
    return "viewer"


def identity_name(role: str, robot: int | None = None) -> str:
    """The username / certificate CN of a process: 'world', 'viewer', 'agent-7', ..."""
    if role not in ROLES:
        raise SecurityError(f"--role {role!r}: not one of {', '.join(ROLES)}")
    if role == "agent":
        if robot is None or not isinstance(robot, int) or robot < 0:
            raise SecurityError(f"--role agent needs a robot id >= 0 (--id), got {robot!r}")
        return f"agent-{robot}"
    return role


def check_name(name: str) -> str:
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise SecurityError(f"identity {name!r}: use lowercase letters, digits and '-'")
    return name


@dataclass(frozen=True)
class Profile:
    """Paths of a profile directory (nothing is read until asked)."""
    root: Path

    @classmethod
    def at(cls, path: str | os.PathLike) -> "Profile":
        root = Path(path).expanduser().resolve()
        if not root.is_dir():
            raise SecurityError(f"--secure {path}: no such directory "
                                f"(create one with `swarmcover secure init {path}`)")
        return cls(root)

    @property
    def ca_cert(self) -> Path:
        return self.root / "ca" / "ca.pem"

    @property
    def ca_key(self) -> Path:
        return self.root / "ca" / "ca.key"

    @property
    def router_dir(self) -> Path:
        return self.root / "router"

    @property
    def router_cert(self) -> Path:
        return self.router_dir / "router.pem"

    @property
    def router_key(self) -> Path:
        return self.router_dir / "router.key"

    @property
    def passwords(self) -> Path:
        return self.router_dir / "passwords.txt"

    @property
    def acl(self) -> Path:
        return self.router_dir / "acl.json5"

    def id_dir(self, name: str) -> Path:
        return self.root / "ids" / check_name(name)

    def identities(self) -> list[str]:
        d = self.root / "ids"
        return sorted(p.name for p in d.iterdir() if p.is_dir()) if d.is_dir() else []

    def password(self, name: str) -> str:
        f = self.id_dir(name) / "password"
        text = _read(f, f"password of {name}").strip()
        if not text or ":" in text or "\n" in text:
            raise SecurityError(f"{f}: expected one password line without ':'")
        return text


def _read(path: Path, what: str) -> str:
    try:
        return path.read_text()
    except OSError as e:
        raise SecurityError(f"{what}: cannot read {path}: {e.strerror or e}") from None


def _need(path: Path, what: str) -> str:
    if not path.is_file():
        raise SecurityError(f"{what}: missing file {path}")
    return str(path)


def secure_endpoints(endpoints: list[str] | None, flag: str) -> list[str] | None:
    """Upgrade ``tcp/`` endpoints to ``tls/``; refuse any other non-TLS link kind."""
    if endpoints is None:
        return None
    out = []
    for e in endpoints:
        if e.startswith("tls/"):
            out.append(e)
        elif e.startswith("tcp/"):
            out.append("tls/" + e[len("tcp/"):])
        else:
            raise SecurityError(f"{flag} {e}: with --secure only tls/ (or tcp/, upgraded to "
                                f"tls/) endpoints are allowed")
    return out


def config_inserts(secure_dir: str, *, mode: str, role: str,
                   robot: int | None = None) -> list[tuple[str, str]]:
    """The Zenoh config ``(path, json5)`` inserts of a profile for one process.

    Router (``mode == "router"``): TLS listen certificate, mutual TLS against the CA, the
    password dictionary and the ACL. Client: the CA, its own certificate and key (mutual
    TLS), and its username/password. Raises :class:`SecurityError` naming the missing file.
    """
    prof = Profile.at(secure_dir)
    ca = _need(prof.ca_cert, f"--secure {secure_dir}")
    ins: list[tuple[str, str]] = [
        ("transport/link/tls/root_ca_certificate", json.dumps(ca)),
        ("transport/link/tls/enable_mtls", "true"),
    ]
    if mode == "router":
        what = f"--secure {secure_dir} (router)"
        ins += [
            ("transport/link/tls/listen_certificate", json.dumps(_need(prof.router_cert, what))),
            ("transport/link/tls/listen_private_key", json.dumps(_need(prof.router_key, what))),
            ("transport/auth/usrpwd/dictionary_file", json.dumps(_need(prof.passwords, what))),
            ("access_control", _read(prof.acl, f"{what} ACL")),
        ]
        return ins
    name = identity_name(role, robot)
    d = prof.id_dir(name)
    what = f"--secure {secure_dir} (identity {name})"
    ins += [
        ("transport/link/tls/connect_certificate", json.dumps(_need(d / "cert.pem", what))),
        ("transport/link/tls/connect_private_key", json.dumps(_need(d / "key.pem", what))),
        ("transport/auth/usrpwd/user", json.dumps(name)),
        ("transport/auth/usrpwd/password", json.dumps(prof.password(name))),
    ]
    return ins
