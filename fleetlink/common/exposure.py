"""Admin surfaces are closed by default: none listens beyond this host without credentials.

``check_exposure`` runs before a server opens its socket: a listen address that is not
loopback with no token configured is a start-up error naming the config key; on loopback
without a token it warns once (anyone on the host can use it).
"""

from __future__ import annotations

import ipaddress
import logging

from fleetlink.common.errors import ConfigError


def is_loopback(host: str) -> bool:
    """``localhost``, ``127.0.0.0/8`` or ``::1`` (a name other than localhost is not trusted to be)."""
    host = host.strip().removeprefix("[").removesuffix("]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_exposure(
    listen: str, *, has_token: bool, key: str, what: str, credentials_from: str, log: logging.Logger
) -> None:
    """Refuse ``listen`` beyond loopback without a token (``ConfigError`` naming ``key``)."""
    host = listen.rpartition(":")[0]
    if has_token:
        return
    if not is_loopback(host):
        raise ConfigError(
            f"{key}: {what} would listen on {listen}, beyond this host, with no access token; set "
            f"{credentials_from}, or listen on 127.0.0.1"
        )
    log.warning(
        "%s on %s has no access token (%s): anyone on this host can use it", what, listen, credentials_from
    )
