"""``swarmcover secure``: certificates, passwords and the ACL of a lab-network profile.

  init DIR     a CA, the router's TLS certificate, one client certificate + password per
               identity (world, coordinator, hwbridge, viewer, live, agent-0..N-1), the
               router's password dictionary and its ACL (default deny)
  export DIR OUT NAME...   copy the CA certificate and only the named identities to OUT
               (what one host needs: a robot computer gets ``agent-7`` and nothing else)
  show DIR     list the identities and what each may publish
  router-config DIR [--listen EP]   a full router config for ``zenohd -c`` (drop-in router)

Then start every process with ``--secure DIR`` (see docs/lab-network.md). The ACL (see
:func:`acl_config`) lets only the world publish bearings (``robot/*/sense``), only the
hwbridge publish live-robot commands (``live/**`` and ROS 2 ``cmd_vel`` keys), each agent
publish only its own robot's ``cmd_vel``/``pose``/``status`` and presence token, and gives
viewers read access only. Key material: ECDSA P-256 keys (PKCS#8 PEM, mode 0600),
X.509 v3 certificates signed by the profile's CA (PyPI ``cryptography``).
"""
from __future__ import annotations

import argparse
import datetime as dt
import ipaddress
import json
import os
import secrets
import shutil
import sys
from pathlib import Path

from swarmcover.bus.security import ROLES, Profile, SecurityError, check_name

DEFAULT_AGENTS = 256
DEFAULT_HOSTS = ("localhost", "127.0.0.1")
SINGLE_IDS = ("world", "coordinator", "hwbridge", "viewer", "live")
P = "sc/*"   # every swarm (experiment) name

# ROS 2 command keys as zenoh-bridge-ros2dds (``<ns>/cmd_vel``) and rmw_zenoh
# (``<domain>/<ns>/cmd_vel/<type>/<hash>``) map them: live-robot commands too.
ROS_CMD_KEYS = ("**/cmd_vel", "**/cmd_vel/**")


# --------------------------------------------------------------------------- ACL (pure)

def _rule(rid: str, flows: list[str], messages: list[str], keys: list[str]) -> dict:
    return {"id": rid, "permission": "allow", "flows": flows, "messages": messages,
            "key_exprs": keys}


def _publish(rid: str, keys: list[str]) -> dict:
    return _rule(rid, ["ingress"], ["put", "delete"], keys)


def _read(rid: str, keys: list[str]) -> dict:
    """Declare a subscriber on ``keys`` and receive their publications."""
    return [_rule(rid + "-sub", ["ingress"], ["declare_subscriber"], keys),
            _rule(rid + "-recv", ["egress"], ["put", "delete"], keys)]


def acl_config(n_agents: int = DEFAULT_AGENTS) -> dict:
    """The ``access_control`` section: default deny, one subject per identity.

    A subject matches a link whose password username AND certificate CN are both the
    identity's name. Rules allow, except one deny that keeps the hwbridge's ROS 2
    ``**/cmd_vel`` grant off the agents' command keys; anything not allowed is dropped.
    """
    if not isinstance(n_agents, int) or n_agents < 0 or n_agents > 100_000:
        raise ValueError(f"--agents {n_agents!r}: expected 0..100000")
    rules: list[dict] = []
    pol: dict[str, list[str]] = {}

    def grant(name: str, *rs):
        for r in rs:
            for x in (r if isinstance(r, list) else [r]):
                if x["id"] not in {y["id"] for y in rules}:
                    rules.append(x)
                pol.setdefault(name, []).append(x["id"])

    # shared by every identity: presence is public, declarations are visible (a publisher
    # learns that someone subscribes), the world's info and clock are readable
    common = [
        _rule("presence-watch", ["ingress"], ["declare_liveliness_subscriber", "liveliness_query"],
              [f"{P}/alive/**"]),
        _rule("presence-see", ["egress"], ["liveliness_token", "reply"], [f"{P}/alive/**"]),
        _rule("see-declarations", ["egress"], ["declare_subscriber", "declare_queryable"],
              ["**"]),
        _rule("info-ask", ["ingress"], ["query"], [f"{P}/world/info"]),
        _rule("info-answer", ["egress"], ["reply"], [f"{P}/world/info"]),
        *_read("clock", [f"{P}/world/clock"]),
    ]
    everyone = [r["id"] for r in common]
    rules += common

    grant("world",
          _publish("world-pub", [f"{P}/robot/*/sense", f"{P}/robot/*/odom",
                                 f"{P}/world/clock", f"{P}/world/truth"]),
          _read("world", [f"{P}/robot/*/cmd_vel", f"{P}/robot/*/twin_cmd",
                          f"{P}/world/spawn", f"{P}/world/remove", f"{P}/coord/ack"]),
          _rule("world-info-serve-decl", ["ingress"], ["declare_queryable", "reply"],
                [f"{P}/world/info"]),
          _rule("world-info-serve-q", ["egress"], ["query"], [f"{P}/world/info"]),
          _rule("world-token", ["ingress"], ["liveliness_token"], [f"{P}/alive/world/**"]))
    grant("coordinator",
          _publish("coord-pub", [f"{P}/robot/*/task", f"{P}/coord/complex",
                                 f"{P}/world/spawn", f"{P}/world/remove", f"{P}/coord/ack"]),
          _read("coord", [f"{P}/robot/*/status"]),
          _rule("coord-token", ["ingress"], ["liveliness_token"], [f"{P}/alive/coordinator/**"]))
    grant("hwbridge",
          _publish("hw-pub", [f"{P}/live/**", *ROS_CMD_KEYS, f"{P}/robot/*/twin_cmd",
                              f"{P}/robot/*/odom", f"{P}/world/spawn"]),
          # ``**/cmd_vel`` would include the agents' own command keys: deny those (a deny
          # rule wins over any allow)
          dict(_publish("hw-not-agent-cmd", [f"{P}/robot/*/cmd_vel", f"{P}/robot/*/cmd_vel/**"]),
               permission="deny"),
          _read("hw", ["**"]),    # mocap may arrive on any (configured) key
          _rule("hw-token", ["ingress"], ["liveliness_token"], [f"{P}/alive/hwbridge/**"]))
    grant("live",
          _publish("live-pub", [f"{P}/mocap/**"]),
          _read("live", [f"{P}/live/**", *ROS_CMD_KEYS]),
          _rule("live-token", ["ingress"], ["liveliness_token"], [f"{P}/alive/live/**"]))
    grant("viewer", _read("viewer", [f"{P}/**"]))
    for i in range(n_agents):
        name = f"agent-{i}"
        grant(name,
              _publish(f"{name}-pub", [f"{P}/robot/{i}/cmd_vel", f"{P}/robot/{i}/pose",
                                       f"{P}/robot/{i}/status"]),
              _read(name, [f"{P}/robot/{i}/sense", f"{P}/robot/{i}/task",
                           f"{P}/robot/{i}/odom"]),
              _rule(f"{name}-token", ["ingress"], ["liveliness_token"],
                    [f"{P}/alive/robot/{i}"]))
    subjects = [{"id": n, "usernames": [n], "cert_common_names": [n]} for n in pol]
    policies = [{"id": f"{n}-policy", "rules": everyone + pol[n], "subjects": [n]} for n in pol]
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}


def allows(acl: dict, name: str, flow: str, message: str, key: str) -> bool:
    """Would ``acl`` let identity ``name`` pass ``message`` on ``key`` in ``flow``?

    Mirrors the router's decision for an allow-only, default-deny ACL: a rule applies when
    one of its key expressions includes ``key`` (zenoh.KeyExpr.includes). For tests and
    ``show``; the router is the authority.
    """
    import zenoh
    ke = zenoh.KeyExpr(key)
    rules = {r["id"]: r for r in acl["rules"]}
    verdicts = set()
    for p in acl["policies"]:
        if name not in p["subjects"]:
            continue
        for rid in p["rules"]:
            r = rules[rid]
            if flow in r["flows"] and message in r["messages"] and any(
                    zenoh.KeyExpr(k).intersects(ke) if r["permission"] == "deny"
                    else zenoh.KeyExpr(k).includes(ke) for k in r["key_exprs"]):
                verdicts.add(r["permission"])
    if "deny" in verdicts:
        return False
    return "allow" in verdicts or acl.get("default_permission") == "allow"


def identities(n_agents: int) -> list[str]:
    return list(SINGLE_IDS) + [f"agent-{i}" for i in range(n_agents)]


# --------------------------------------------------------------------------- key material

def _x509():
    try:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID
    except ImportError:
        raise SystemExit("swarmcover secure needs the PyPI package `cryptography` "
                         "(pip install cryptography)") from None
    return x509, hashes, serialization, ec, ExtendedKeyUsageOID, NameOID


def _write(path: Path, data: bytes | str, private: bool = False) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600 if private else 0o644)
    with os.fdopen(fd, "wb") as f:
        f.write(data)


class _Issuer:
    """A CA that signs leaf certificates (ECDSA P-256, SHA-256)."""

    def __init__(self, days: int, org: str):
        x509, hashes, serialization, ec, EKU, NameOID = _x509()
        self.m = (x509, hashes, serialization, ec, EKU, NameOID)
        self.days, self.org = days, org
        self.key = ec.generate_private_key(ec.SECP256R1())
        name = x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, org),
                          x509.NameAttribute(NameOID.COMMON_NAME, f"{org} CA")])
        now = dt.datetime.now(dt.timezone.utc)
        pub = self.key.public_key()
        self.cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name)
                     .public_key(pub).serial_number(x509.random_serial_number())
                     .not_valid_before(now - dt.timedelta(minutes=5))
                     .not_valid_after(now + dt.timedelta(days=days))
                     .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
                     .add_extension(x509.KeyUsage(False, False, False, False, False, True, True,
                                                  False, False), critical=True)
                     .add_extension(x509.SubjectKeyIdentifier.from_public_key(pub), critical=False)
                     .sign(self.key, hashes.SHA256()))

    def pem(self, cert) -> bytes:
        return cert.public_bytes(self.m[2].Encoding.PEM)

    def key_pem(self, key) -> bytes:
        s = self.m[2]
        return key.private_bytes(s.Encoding.PEM, s.PrivateFormat.PKCS8, s.NoEncryption())

    def issue(self, cn: str, hosts: list[str], server: bool) -> tuple[bytes, bytes]:
        """(certificate PEM, key PEM) for ``cn`` with SANs ``hosts`` (DNS names or IPs)."""
        x509, hashes, _, ec, EKU, NameOID = self.m
        key = ec.generate_private_key(ec.SECP256R1())
        now = dt.datetime.now(dt.timezone.utc)
        sans = []
        for h in hosts:
            try:
                sans.append(x509.IPAddress(ipaddress.ip_address(h)))
            except ValueError:
                sans.append(x509.DNSName(h))
        usages = [EKU.CLIENT_AUTH] + ([EKU.SERVER_AUTH] if server else [])
        cert = (x509.CertificateBuilder()
                .subject_name(x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, self.org),
                                         x509.NameAttribute(NameOID.COMMON_NAME, cn)]))
                .issuer_name(self.cert.subject).public_key(key.public_key())
                .serial_number(x509.random_serial_number())
                .not_valid_before(now - dt.timedelta(minutes=5))
                .not_valid_after(now + dt.timedelta(days=self.days))
                .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
                .add_extension(x509.KeyUsage(True, False, False, False, False, False, False,
                                             False, False), critical=True)
                .add_extension(x509.ExtendedKeyUsage(usages), critical=False)
                .add_extension(x509.SubjectAlternativeName(sans), critical=False)
                .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(
                    self.key.public_key()), critical=False)
                .sign(self.key, hashes.SHA256()))
        return self.pem(cert), self.key_pem(key)


def init_profile(root: str | os.PathLike, n_agents: int = DEFAULT_AGENTS,
                 hosts: list[str] | tuple[str, ...] = DEFAULT_HOSTS, days: int = 365,
                 force: bool = False, org: str = "swarmcover") -> Profile:
    """Write a complete profile to ``root`` (see bus/security.py for the layout)."""
    root = Path(root).expanduser()
    acl = acl_config(n_agents)          # validates n_agents first
    if days < 1:
        raise ValueError(f"--days {days}: expected >= 1")
    hosts = list(dict.fromkeys(hosts))
    if not hosts:
        raise ValueError("--host: at least one router host name or IP is needed")
    if root.exists() and any(root.iterdir()):
        if not force:
            raise SecurityError(f"{root}: not empty (use --force to replace the profile)")
        for sub in ("ca", "router", "ids"):
            shutil.rmtree(root / sub, ignore_errors=True)
    root.mkdir(parents=True, exist_ok=True)
    prof = Profile(root.resolve())
    ca = _Issuer(days, org)
    _write(prof.ca_cert, ca.pem(ca.cert))
    _write(prof.ca_key, ca.key_pem(ca.key), private=True)
    cert, key = ca.issue("router", hosts, server=True)
    _write(prof.router_cert, cert)
    _write(prof.router_key, key, private=True)
    lines = []
    for name in identities(n_agents):
        cert, key = ca.issue(name, [name], server=False)
        pw = secrets.token_urlsafe(24)
        d = prof.id_dir(name)
        _write(d / "cert.pem", cert)
        _write(d / "key.pem", key, private=True)
        _write(d / "password", pw + "\n", private=True)
        lines.append(f"{name}:{pw}")
    _write(prof.passwords, "\n".join(lines) + "\n", private=True)
    _write(prof.acl, json.dumps(acl, indent=1) + "\n", private=True)
    _write(prof.root / "profile.json", json.dumps(
        {"version": 1, "agents": n_agents, "hosts": hosts, "days": days, "roles": list(ROLES),
         "created": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")},
        indent=1) + "\n")
    return prof


def export_profile(src: str | os.PathLike, out: str | os.PathLike, names: list[str],
                   router: bool = False) -> Path:
    """Copy the CA certificate and only the named identities (and the router's files when
    ``router``) to ``out``: the minimal profile for one host. The CA key never leaves."""
    prof = Profile.at(src)
    out = Path(out).expanduser()
    dst = Profile(out.resolve())
    todo = []
    for n in names:
        d = prof.id_dir(check_name(n))
        if not d.is_dir():
            raise SecurityError(f"identity {n!r}: not in {prof.root} "
                                f"(have: {', '.join(prof.identities()[:8])} ...)")
        todo.append((d, dst.id_dir(n)))
    out.mkdir(parents=True, exist_ok=True)
    _write(dst.ca_cert, prof.ca_cert.read_bytes())
    for a, b in todo:
        for f in ("cert.pem", "key.pem", "password"):
            _write(b / f, (a / f).read_bytes(), private=f != "cert.pem")
    if router:
        for f in (prof.router_cert, prof.router_key, prof.passwords, prof.acl):
            _write(dst.router_dir / f.name, f.read_bytes(), private=f != prof.router_cert)
    return out


def router_config(src: str | os.PathLike, listen: list[str]) -> dict:
    """A complete router config (JSON, valid JSON5) for this profile: for ``zenohd -c FILE``
    or ``swarmcover router --config FILE``. ``listen``: tls/ endpoints (tcp/ is upgraded)."""
    from swarmcover.bus.security import secure_endpoints
    prof = Profile.at(src)
    for f in (prof.ca_cert, prof.router_cert, prof.router_key, prof.passwords, prof.acl):
        if not f.is_file():
            raise SecurityError(f"router config: missing {f}")
    return {
        "mode": "router",
        "listen": {"endpoints": secure_endpoints(list(listen), "--listen")},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {
            "link": {"tls": {"root_ca_certificate": str(prof.ca_cert),
                             "listen_certificate": str(prof.router_cert),
                             "listen_private_key": str(prof.router_key),
                             "enable_mtls": True}},
            "auth": {"usrpwd": {"dictionary_file": str(prof.passwords)}},
        },
        "access_control": json.loads(prof.acl.read_text()),
    }


def describe(src: str | os.PathLike) -> str:
    """A human summary of a profile: identities and the keys each may publish."""
    prof = Profile.at(src)
    acl = json.loads(prof.acl.read_text()) if prof.acl.is_file() else None
    lines = [f"profile {prof.root}", f"  CA: {prof.ca_cert}"]
    ids = prof.identities()
    lines.append(f"  identities ({len(ids)}): " + ", ".join(ids[:10]) + (" ..." if len(ids) > 10 else ""))
    if acl:
        rules = {r["id"]: r for r in acl["rules"]}
        for p in acl["policies"]:
            subj = p["subjects"][0]
            if subj.startswith("agent-") and subj not in ("agent-0",):
                continue
            def keys(perm):
                return [k for rid in p["rules"] for k in rules[rid]["key_exprs"]
                        if rules[rid]["permission"] == perm and "ingress" in rules[rid]["flows"]
                        and "put" in rules[rid]["messages"]]
            deny = keys("deny")
            lines.append(f"  {subj:<12} may publish: {', '.join(keys('allow')) or '(nothing)'}"
                         + (f" except {', '.join(deny)}" if deny else ""))
        lines.append("  (agent-<i> like agent-0, with its own id)")
    return "\n".join(lines)


# --------------------------------------------------------------------------- command

def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="swarmcover secure", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    pi = sub.add_parser("init", help="generate a new profile")
    pi.add_argument("dir")
    pi.add_argument("--agents", type=int, default=DEFAULT_AGENTS,
                    help=f"per-robot credentials for agent-0..agent-N-1 (default {DEFAULT_AGENTS})")
    pi.add_argument("--host", action="append", default=None, metavar="NAME_OR_IP",
                    help="router host name or IP the clients connect to, repeatable "
                         f"(default: {', '.join(DEFAULT_HOSTS)})")
    pi.add_argument("--days", type=int, default=365, help="certificate validity (default 365)")
    pi.add_argument("--force", action="store_true", help="replace an existing profile")
    pe = sub.add_parser("export", help="copy the CA and the named identities for one host")
    pe.add_argument("dir")
    pe.add_argument("out")
    pe.add_argument("names", nargs="*", help="identities, e.g. agent-7 world")
    pe.add_argument("--router", action="store_true", help="include the router's files")
    ps = sub.add_parser("show", help="list identities and what each may publish")
    ps.add_argument("dir")
    pr = sub.add_parser("router-config", help="print a zenohd / `swarmcover router --config` "
                        "config file for this profile")
    pr.add_argument("dir")
    pr.add_argument("--listen", action="append", default=None, metavar="ENDPOINT",
                    help="tls/ endpoint to listen on, repeatable (default tls/0.0.0.0:7447)")
    args = p.parse_args(argv)
    try:
        if args.cmd == "init":
            prof = init_profile(args.dir, args.agents, args.host or DEFAULT_HOSTS, args.days,
                                args.force)
            print(f"profile written to {prof.root}: CA, router ({', '.join(args.host or DEFAULT_HOSTS)}), "
                  f"{len(identities(args.agents))} identities; start processes with "
                  f"--secure {args.dir}")
        elif args.cmd == "export":
            if not args.names and not args.router:
                p.error("export: name at least one identity or --router")
            out = export_profile(args.dir, args.out, args.names, args.router)
            print(f"exported {', '.join(args.names + (['router'] if args.router else []))} to {out}")
        elif args.cmd == "router-config":
            print(json.dumps(router_config(args.dir, args.listen or ["tls/0.0.0.0:7447"]),
                             indent=1))
        else:
            print(describe(args.dir))
    except (SecurityError, ValueError, OSError) as e:
        print(f"swarmcover secure: {e}", file=sys.stderr)
        return 2
    return 0
