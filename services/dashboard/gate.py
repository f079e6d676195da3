"""Who may use the dashboard: the Host and Origin of every request, HTTP and websocket alike.

A page of any other site can make a browser send requests to 127.0.0.1 (a form, a fetch, a
websocket), and the dashboard has no login. Two checks stop it, before any route runs:

- **Host**: the name the browser used must be one of the dashboard's own: 127.0.0.1,
  localhost, [::1], the address it listens on, and the names ``PNAV_DASHBOARD_ALLOWED_HOSTS``
  adds. DNS rebinding (a site's own name pointed at 127.0.0.1 once its page is loaded) comes
  with that site's name, and is refused. Listening on every address (0.0.0.0, ::), any IP
  address is also the dashboard's own: an address cannot be pointed elsewhere, only a name.
- **Origin**: when a browser names the page that made the request, it must be exactly
  ``http://<Host>``: scheme, host and port of the dashboard's page as the browser loaded it
  (https, another port or another name is another site). A client that is not a browser
  (curl, a script) sends no Origin, and passes on its Host alone.

A refusal is 403 with ``{"error": reason}``; a refused websocket handshake is answered 403.
"""

from __future__ import annotations

import ipaddress
import logging
from dataclasses import dataclass
from urllib.parse import urlsplit

from starlette.datastructures import Headers
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send

from services.dashboard.settings import DashboardSettings

logger = logging.getLogger("pnav.dashboard.gate")

LOOPBACK_NAMES = ("127.0.0.1", "localhost", "::1")
_WILDCARDS = ("0.0.0.0", "::", "")


def _address(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


def _normal(name: str) -> str:
    """A host name as compared: lower case, no brackets, no trailing dot."""
    return name.strip("[]").rstrip(".").lower()


@dataclass(frozen=True)
class AllowedHosts:
    names: frozenset[str]
    any_address: bool = False  # listening on every address: every IP literal is its own

    @classmethod
    def of(cls, settings: DashboardSettings) -> AllowedHosts:
        host = _normal(settings.host)
        names = {*LOOPBACK_NAMES, *(_normal(n) for n in settings.allowed_hosts)}
        if host not in _WILDCARDS:
            names.add(host)
        return cls(frozenset(names), any_address=host in _WILDCARDS)

    def allows(self, name: str) -> bool:
        name = _normal(name)
        return name in self.names or (self.any_address and _address(name))

    def refusal(self, host: str | None, origin: str | None) -> str | None:
        """Why a request with these Host and Origin headers is refused; None: it is not."""
        if not host:
            return "no Host header: say which address the dashboard was reached at"
        try:
            where = urlsplit(f"//{host}")
            name, port = where.hostname, where.port
        except ValueError:
            return f"Host {host[:100]!r} is not a host and port"
        if not name or where.username is not None or where.path or not self.allows(name):
            return (
                f"Host {host[:100]!r} is not one of the dashboard's own names "
                "(127.0.0.1, localhost, [::1] and PNAV_DASHBOARD_ALLOWED_HOSTS): "
                "refused, as a page of another site reaching it by DNS rebinding would be"
            )
        if origin is None:
            return None
        try:
            page = urlsplit(origin)
            same = (page.scheme, page.hostname, page.port or 80, page.path, page.query) == (
                "http",
                name,
                port or 80,
                "",
                "",
            )
        except ValueError:
            same = False
        if not same or page.username is not None:
            return (
                f"cross-origin request from {origin[:100]} refused: the dashboard's page is "
                f"http://{host}, use it"
            )
        return None


class Gate:
    """ASGI middleware: :meth:`AllowedHosts.refusal` for every HTTP request and websocket."""

    def __init__(self, app: ASGIApp, allowed: AllowedHosts) -> None:
        self.app, self.allowed = app, allowed

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = Headers(scope=scope)
        reason = self.allowed.refusal(headers.get("host"), headers.get("origin"))
        if reason is None:
            await self.app(scope, receive, send)
            return
        logger.warning("%s %s: %s", scope["type"], scope.get("path", ""), reason)
        if scope["type"] == "websocket":
            # closing before accepting: the server answers the handshake 403
            await send({"type": "websocket.close", "code": 1008})
            return
        await JSONResponse({"error": reason}, status_code=403)(scope, receive, send)
