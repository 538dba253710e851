"""Who may operate a run's page: a users file of names, roles and password hashes.

Writing from the page needs a login (viewing on the loopback interface needs none). The
users are a TOML file (``--hmi-users USERS.toml``) that holds, for each name, its role
(:data:`cosim.core.operator.ROLES`) and the scrypt hash of its password, never the password::

    [users.ops]
    role = "operator"
    password = "scrypt$16384$8$1$<salt>$<hash>"

``python -m cosim.hmi.users USERS.toml NAME ROLE`` adds or replaces a user, the password
read from ``$COSIM_HMI_PASSWORD`` or a prompt (never from the command line).
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import os
import secrets
import sys
from collections.abc import Sequence
from pathlib import Path

from cosim.core import atomicio
from cosim.core.errors import CosimError
from cosim.core.operator import ROLES, users_table
from cosim.hmi.actions import User

__all__ = ["PASSWORD_ENV", "Users", "hash_password", "main"]

#: The environment variable a new user's password is read from (else a prompt).
PASSWORD_ENV = "COSIM_HMI_PASSWORD"
_SCRYPT = (16384, 8, 1)   # n, r, p: about 16 MiB and 50 ms per check


def hash_password(password: str) -> str:
    """The scrypt hash of ``password`` with a random salt, as the users file holds it."""
    n, r, p = _SCRYPT
    salt = secrets.token_bytes(16)
    digest = hashlib.scrypt(password.encode(), salt=salt, n=n, r=r, p=p, dklen=32)
    b64 = base64.b64encode
    return f"scrypt${n}${r}${p}${b64(salt).decode()}${b64(digest).decode()}"


def _matches(password: str, stored: str) -> bool:
    """Whether ``password`` hashes to ``stored`` (compared in constant time)."""
    try:
        kind, n, r, p, salt, digest = stored.split("$")
        if kind != "scrypt":
            return False
        got = hashlib.scrypt(password.encode(), salt=base64.b64decode(salt), n=int(n),
                             r=int(r), p=int(p), dklen=32)
        return hmac.compare_digest(got, base64.b64decode(digest))
    except (ValueError, TypeError):
        return False


class Users:
    """The users of a page: ``{name: (role, password hash)}``."""

    def __init__(self, users: dict[str, tuple[str, str]], source: str = "") -> None:
        self.users = dict(users)
        self.source = source

    @staticmethod
    def load(path: str | Path, flag: str = "--hmi-users") -> Users:
        """Read a users file.

        Raises
        ------
        CosimError
            The file is missing, not TOML, or a user has no valid role or hash: one line
            naming the file (and the user).
        """
        path = Path(path)
        table = users_table(path, flag, "role and password")
        users = {}
        for name, entry in table.items():
            role = entry.get("role") if isinstance(entry, dict) else None
            stored = entry.get("password") if isinstance(entry, dict) else None
            if role not in ROLES:
                raise CosimError(f"{path}: users.{name}.role: expected one of "
                                 f"{', '.join(ROLES)}, got {role!r}")
            if not isinstance(stored, str) or not stored.startswith("scrypt$") \
                    or stored.count("$") != 5:
                raise CosimError(f"{path}: users.{name}.password: expected a scrypt hash "
                                 "(python -m cosim.hmi.users writes one), not a password")
            users[str(name)] = (role, stored)
        return Users(users, str(path))

    def check(self, name: str, password: str) -> User | None:
        """The user ``name`` when ``password`` is theirs, else ``None``."""
        entry = self.users.get(name)
        if entry is None:
            _matches(password, hash_password("-"))   # the same time for an unknown name
            return None
        return User(name, entry[0]) if _matches(password, entry[1]) else None

    def write(self, path: str | Path) -> None:
        """Write the users file (atomically)."""
        lines = ["# who may operate the page of cosim run/view --hmi (python -m cosim.hmi.users)"]
        for name, (role, stored) in sorted(self.users.items()):
            lines += ["", f'[users."{name}"]', f'role = "{role}"', f'password = "{stored}"']
        atomicio.write_text(path, "\n".join(lines) + "\n")


def _read_new_password(name: str) -> str:
    password = os.environ.get(PASSWORD_ENV)
    if password is not None:
        return password
    if sys.stdin is not None and sys.stdin.isatty():
        import getpass

        first = getpass.getpass(f"password of {name}: ")
        if getpass.getpass("again: ") != first:
            raise CosimError("the two passwords differ")
        return first
    raise CosimError(f"no password for {name}: set ${PASSWORD_ENV} (it is never taken from "
                     "the command line)")


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m cosim.hmi.users USERS.toml NAME ROLE``: add or replace a user."""
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 3 or args[2] not in ROLES or not args[1].replace("-", "").replace(
            "_", "").isalnum():
        print(f"usage: python -m cosim.hmi.users USERS.toml NAME {{{','.join(ROLES)}}} "
              f"(the password from ${PASSWORD_ENV} or a prompt)", file=sys.stderr)
        return 2
    path, name, role = Path(args[0]), args[1], args[2]
    try:
        users = Users.load(path) if path.exists() else Users({})
        password = _read_new_password(name)
        if not password:
            raise CosimError("an empty password")
    except CosimError as exc:
        print(f"cosim.hmi.users: error: {exc}", file=sys.stderr)
        return 2
    users.users[name] = (role, hash_password(password))
    users.write(path)
    print(f"cosim.hmi.users: {name} ({role}) in {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
