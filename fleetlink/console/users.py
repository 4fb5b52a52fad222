"""Named console users with roles, and their hashed secrets (pure apart from reading the file).

A users file (``console.users_file``, or ``$FLEETLINK_CONSOLE_USERS_FILE``) lists who may sign
in, with what role and the scrypt hash of their password::

    users:
      - {name: ada, role: admin, password_hash: "scrypt$16384$8$1$<salt>$<hash>"}
      - {name: lin, role: operator, password_hash: "scrypt$..."}
      - {name: sam, role: viewer, password_hash: "scrypt$..."}

``fleetlink console hash-password`` prints a hash for a password read from standard input;
plain passwords are never stored. Roles nest: a ``viewer`` reads every page; an ``operator``
also sends commands and adds, changes and removes mappings; an ``admin`` also edits robot types.
A file that does not validate is a start-up error naming the YAML path (``users[1].role``).
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import os
import re
import secrets
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, cast

import yaml

from fleetlink.console.errors import ConsoleConfigError

Role = Literal["viewer", "operator", "admin"]
ROLES: tuple[Role, ...] = ("viewer", "operator", "admin")
USERS_FILE_ENV = "FLEETLINK_CONSOLE_USERS_FILE"
_NAME = re.compile(r"^[A-Za-z0-9_.@-]{1,64}$")
_SCRYPT = {"n": 2**14, "r": 8, "p": 1}


def role_at_least(role: str, needed: Role) -> bool:
    """Whether ``role`` is a known role at or above ``needed`` (viewer < operator < admin)."""
    return role in ROLES and ROLES.index(role) >= ROLES.index(needed)


def _b64(data: bytes) -> str:
    return base64.urlsafe_b64encode(data).decode().rstrip("=")


def _unb64(text: str) -> bytes:
    return base64.urlsafe_b64decode(text + "=" * (-len(text) % 4))


def hash_password(password: str, *, salt: bytes | None = None) -> str:
    """``scrypt$<n>$<r>$<p>$<salt>$<hash>`` (base64url): what the users file holds."""
    salt = salt if salt is not None else secrets.token_bytes(16)
    n, r, p = _SCRYPT["n"], _SCRYPT["r"], _SCRYPT["p"]
    digest = hashlib.scrypt(password.encode(), salt=salt, n=n, r=r, p=p, dklen=32)
    return f"scrypt${n}${r}${p}${_b64(salt)}${_b64(digest)}"


def hash_problem(stored: str) -> str | None:
    """Why a stored password hash is unusable (``None``: a well-formed scrypt hash, sane parameters)."""
    parts = stored.split("$")
    if len(parts) != 6 or parts[0] != "scrypt" or not all(x.isdigit() for x in parts[1:4]):
        return "is not a password hash of 'fleetlink console hash-password' (scrypt$n$r$p$salt$hash)"
    n, r, p = (int(x) for x in parts[1:4])
    if n < 2**10 or n > 2**20 or n & (n - 1) or not 1 <= r <= 32 or not 1 <= p <= 16:
        return "has scrypt parameters out of range"
    try:
        if len(_unb64(parts[4])) < 8 or len(_unb64(parts[5])) != 32:
            return "has a salt or hash of the wrong length"
    except ValueError:
        return "has a salt or hash that is not base64"
    return None


def verify_password(stored: str, given: str) -> bool:
    """Constant-time check of ``given`` against a stored hash (``False`` for a malformed one)."""
    if hash_problem(stored) is not None:
        return False
    _, n, r, p, salt, digest = stored.split("$")
    computed = hashlib.scrypt(
        given.encode(), salt=_unb64(salt), n=int(n), r=int(r), p=int(p), dklen=32, maxmem=2**26
    )
    return hmac.compare_digest(computed, _unb64(digest))


@dataclass(frozen=True, slots=True)
class User:
    """A named console user: their name, role and the scrypt hash of their password."""

    name: str
    role: Role
    password_hash: str

    @property
    def fingerprint(self) -> str:
        """Changes when the password or the role does: signs the user's sessions out."""
        return hashlib.sha256(f"{self.role}\0{self.password_hash}".encode()).hexdigest()[:32]


def parse_users(data: object, *, source: str) -> dict[str, User]:
    """The users of a parsed users file; ``ConsoleConfigError`` names the YAML path of each problem."""
    problems: list[str] = []
    entries = data.get("users") if isinstance(data, Mapping) else None
    if not isinstance(entries, list):
        raise ConsoleConfigError(f"{source}: users: a list of {{name, role, password_hash}} is expected")
    users: dict[str, User] = {}
    for i, entry in enumerate(entries):
        where = f"users[{i}]"
        if not isinstance(entry, Mapping):
            problems.append(f"{where}: a mapping {{name, role, password_hash}} is expected")
            continue
        unknown = sorted(set(entry) - {"name", "role", "password_hash"})
        if unknown:
            problems.append(f"{where}.{unknown[0]}: not a key of a user")
        name, role, stored = entry.get("name"), entry.get("role"), entry.get("password_hash")
        if not isinstance(name, str) or not _NAME.match(name):
            problems.append(f"{where}.name: 1 to 64 of A-Z a-z 0-9 _ . @ - expected")
        elif name in users:
            problems.append(f"{where}.name: {name!r} is listed twice")
        if role not in ROLES:
            problems.append(f"{where}.role: one of {', '.join(ROLES)} expected")
        problem = hash_problem(stored) if isinstance(stored, str) else "is missing"
        if problem is not None:
            problems.append(f"{where}.password_hash: {problem}")
        if isinstance(name, str) and role in ROLES and isinstance(stored, str) and problem is None:
            users.setdefault(name, User(name, cast("Role", role), stored))
    if problems:
        raise ConsoleConfigError(f"{source}: " + "; ".join(problems))
    return users


def load_users(file: Path | None, env: Mapping[str, str] | None = None) -> dict[str, User]:
    """The users of ``file`` (or of ``$FLEETLINK_CONSOLE_USERS_FILE``); none when neither is set."""
    env = os.environ if env is None else env
    path = file if file is not None else (Path(env[USERS_FILE_ENV]) if env.get(USERS_FILE_ENV) else None)
    if path is None:
        return {}
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConsoleConfigError(f"{path}: cannot read the console users file: {exc.strerror}") from None
    except yaml.YAMLError as exc:
        raise ConsoleConfigError(f"{path}: not valid YAML: {exc}") from None
    return parse_users(data, source=str(path))
