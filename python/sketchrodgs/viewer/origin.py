"""Only the viewer's own page (and origins the user allows) may open its websocket.

A browser lets any web page open a websocket to any address, 127.0.0.1 included: the same-origin
policy does not apply to websockets. Unchecked, a page open in another tab could connect to the
viewer on this machine, receive the scene and drive the panel. Browsers send the page's origin
with every websocket handshake, so the viewer closes (code 1008, before sending anything) each
connection whose `Origin` is not one of `allowed_origins`: the page as served on a loopback name
(`http://127.0.0.1:PORT`, `http://localhost:PORT`, `http://[::1]:PORT`), on the host it was told
to listen on when that is a name or an address (not 0.0.0.0), and origins given with
`--allow-origin`. A connection without an `Origin` header is not a web page (a script on this
machine, which could read the scene file as well) and is let in.

viser 1.1 has no hook in the handshake; the check is its websocket server's first per-connection
callback, which runs before the connection's message producers start.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
from collections.abc import Iterable
from typing import Any
from urllib.parse import urlsplit

import viser

from ..errors import SketchRodGSError

logger = logging.getLogger("sketchrodgs")

LOOPBACK_NAMES = ("127.0.0.1", "localhost", "::1")
WILDCARDS = ("", "0.0.0.0", "::")
POLICY_VIOLATION = 1008  # websocket close code: the server refuses the connection by policy

Origin = tuple[str, str, int]  # scheme, host (lower case), port


def parse_origin(text: str) -> Origin:
    """`scheme://host[:port]` -> (scheme, host, port), the port defaulting by scheme.

    Raises:
        SketchRodGSError: not an http(s) origin (a path, query or user name is not an origin).
    """
    try:
        parts = urlsplit(text.strip())
        port = parts.port
    except ValueError:
        parts, port = None, None
    if (
        parts is None
        or parts.scheme not in ("http", "https")
        or not parts.hostname
        or parts.path not in ("", "/")
        or parts.query
        or parts.fragment
        or parts.username is not None
    ):
        raise SketchRodGSError(f"expected a page origin such as http://myhost:8080, got {text!r}")
    return parts.scheme, parts.hostname.lower(), port if port is not None else (443 if parts.scheme == "https" else 80)


def is_loopback(host: str) -> bool:
    """Whether `host` (a --host value) only serves this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def allowed_origins(host: str, port: int, extra: Iterable[str] = ()) -> frozenset[Origin]:
    """The origins whose pages may connect to a viewer listening on `host`:`port`."""
    names = set(LOOPBACK_NAMES)
    if host not in WILDCARDS:
        names.add(host)
    origins = {("http", name.lower().strip("[]"), port) for name in names}
    return frozenset(origins | {parse_origin(origin) for origin in extra})


class OriginGuard:
    """Closes the websocket connections of pages from other origins.

    Args:
        server: the viser server (install the guard before adding anything to the scene).
        allowed: the origins let in.

    Attributes:
        refused: how many connections were refused.
    """

    def __init__(self, server: viser.ViserServer, allowed: Iterable[Origin]) -> None:
        self.allowed = frozenset(allowed)
        self.refused = 0
        self._websocket = server._websock_server  # viser 1.1: no public handshake hook
        self._websocket.on_client_connect(self._check)
        loop = server.get_event_loop()
        for client_id in list(self._websocket._live_connections):  # any that came before the guard
            asyncio.run_coroutine_threadsafe(self._close_if_foreign(client_id), loop)

    def allows(self, origin: str | None) -> bool:
        """Whether a handshake with this `Origin` header is let in."""
        if origin is None:
            return True
        try:
            return parse_origin(origin) in self.allowed
        except SketchRodGSError:
            return False

    async def _check(self, connection: Any) -> None:
        await self._close_if_foreign(connection.client_id)

    async def _close_if_foreign(self, client_id: int) -> None:
        connection = self._websocket._live_connections.get(client_id)
        if connection is None:
            return
        origin = connection.request.headers.get("Origin") if connection.request is not None else None
        if self.allows(origin):
            return
        self.refused += 1
        logger.warning(
            "refused a connection from a page at %s (sketchrodgs view --allow-origin %s lets it in)", origin, origin
        )
        await connection.close(POLICY_VIOLATION, "this page's origin may not use the viewer")
