"""``fleetlink console hash-password``: a password hash for the console's users file.

Reads the password from standard input (one line; a terminal does not echo it) and prints
``scrypt$<n>$<r>$<p>$<salt>$<hash>`` for ``password_hash`` in the users file (docs/console.md,
"Access"). Nothing else is written anywhere.
"""

from __future__ import annotations

import argparse
import getpass
import sys
from typing import Any


def register(sub: Any) -> None:
    """Add ``fleetlink console hash-password`` to the subcommands."""
    console = sub.add_parser("console", help="the web console's users (password hashes)")
    actions = console.add_subparsers(dest="console_command", metavar="ACTION", required=True)
    hashing = actions.add_parser(
        "hash-password",
        help="print the hash of a password read from standard input, for the console's users file",
    )
    hashing.set_defaults(handler=_hash_password)


def _hash_password(_args: argparse.Namespace) -> int:
    from fleetlink.console.users import hash_password

    tty = sys.stdin.isatty()
    password = getpass.getpass("password: ") if tty else sys.stdin.readline().rstrip("\r\n")
    if len(password) < 8:
        print("fleetlink: a console password has at least 8 characters", file=sys.stderr)
        return 2
    print(hash_password(password))
    return 0
