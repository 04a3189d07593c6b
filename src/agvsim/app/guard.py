"""Who may drive the browser app: only a browser that opened the URL printed at start-up.

Any web page open in the user's browser can open ``ws://127.0.0.1:8080`` (a browser lets
pages open websockets to any address), so without a check any site could watch the
simulation and press the app's buttons: cross-site websocket hijacking. Two checks stop it,
made on every HTTP request and websocket handshake before viser sees it:

1. **A per-launch token**, as Jupyter has: the URL printed at start-up ends in
   ``?token=...`` (a fresh random secret each launch). The page request that carries it gets
   it back as a cookie (``HttpOnly``, ``SameSite=Strict``, named after the port); the page's
   websocket handshake must carry that cookie, or ``?token=`` itself (scripts). Other sites
   cannot read the cookie, and a strict cookie is not sent with their requests; a site that
   points its own domain name at 127.0.0.1 (DNS rebinding) is another site to the browser.
2. **The Origin**: a browser names the page that opens a websocket in its ``Origin`` header;
   it must be the app's own address (the ``Host`` the request was sent to). A client that
   sends no Origin is not a browser page and needs the token all the same.

The page itself (viser's client) is served only with the token or the cookie, so that someone
who opens the bare address reads how to get in instead of a client that cannot connect.

Viser (1.x) starts its websockets server inside ``ViserServer()`` and has no hook for the
handshake. :func:`start_guarded` wraps ``websockets.asyncio.server.serve`` while that
constructor runs (under a lock, put back at once) to chain :meth:`Guard.process_request`
before viser's own handler; if viser did not call it, the server is stopped and an error
raised: a viser upgrade cannot silently drop the protection.
"""

from __future__ import annotations

import hmac
import http
import secrets
import threading
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from http.cookies import CookieError, SimpleCookie
from typing import Any, TypeVar
from urllib.parse import parse_qs, urlsplit

_PATCH_LOCK = threading.Lock()

T = TypeVar("T")

REFUSED_PAGE = (
    "This agvsim app is open only to the browser that opened its address with the token "
    "(?token=...), as printed by the command that started it. Open that address.\n"
)


def new_token() -> str:
    return secrets.token_urlsafe(24)  # 192 random bits


def app_url(host: str, port: int, token: str) -> str:
    """The address to open (printed at start-up): ``http://HOST:PORT/?token=...``; a wildcard
    host is shown as 127.0.0.1."""
    shown = "127.0.0.1" if host in ("", "0.0.0.0", "::") else host
    if ":" in shown:  # an IPv6 address
        shown = f"[{shown}]"
    return f"http://{shown}:{port}/?token={token}"


@dataclass
class Guard:
    """The checks of one app (see the module docstring). ``refused`` counts the requests
    turned away (for tests and logs)."""

    token: str = field(default_factory=new_token)
    refused: int = 0

    def cookie_name(self, port: int) -> str:
        return f"agvsim_token_{port}"

    def _token_ok(self, given: str | None) -> bool:
        return given is not None and hmac.compare_digest(given.encode(), self.token.encode())

    def _cookie(self, header: str | None, port: int) -> str | None:
        if not header:
            return None
        jar: SimpleCookie = SimpleCookie()
        try:
            jar.load(header)
        except CookieError:
            return None
        morsel = jar.get(self.cookie_name(port))
        return None if morsel is None else morsel.value

    @staticmethod
    def same_origin(origin: str, host: str | None) -> bool:
        """Whether a browser's ``Origin`` is the address the request was sent to."""
        if not host:
            return False
        parts = urlsplit(origin)
        return parts.scheme in ("http", "https") and parts.netloc.lower() == host.lower()

    def process_request(
        self, connection: Any, request: Any, inner: Callable[[Any, Any], Any] | None
    ) -> Any:
        """websockets' ``process_request``: a 403 response for a request to refuse, else
        ``inner``'s answer (viser's: a file, or None to go on with the websocket), with the
        token cookie set when the token came in the URL."""
        headers = request.headers
        port = int(connection.local_address[1])
        query = parse_qs(urlsplit(request.path).query).get("token", [])
        from_query = query[0] if query else None
        authorised = self._token_ok(from_query) or self._token_ok(
            self._cookie(headers.get("Cookie"), port)
        )
        is_websocket = headers.get("Upgrade", "").lower() == "websocket"
        origin = headers.get("Origin")
        if is_websocket and origin is not None and not self.same_origin(origin, headers["Host"]):
            return self._refuse(connection, f"websocket from another origin ({origin}) refused")
        if not authorised:
            return self._refuse(connection, REFUSED_PAGE)
        response = inner(connection, request) if inner is not None else None
        if not self._token_ok(from_query):
            return response
        if isinstance(response, Awaitable):
            return self._with_cookie_later(response, port)
        return self._with_cookie(response, port)

    def _with_cookie(self, response: Any, port: int) -> Any:
        if response is not None:
            response.headers["Set-Cookie"] = (
                f"{self.cookie_name(port)}={self.token}; Path=/; HttpOnly; SameSite=Strict"
            )
        return response

    async def _with_cookie_later(self, response: Awaitable[Any], port: int) -> Any:
        return self._with_cookie(await response, port)

    def _refuse(self, connection: Any, text: str) -> Any:
        self.refused += 1
        return connection.respond(http.HTTPStatus.FORBIDDEN, text)


def open_viser(host: str, port: int, verbose: bool = False) -> tuple[Any, Guard]:
    """A ``viser.ViserServer`` on ``host:port`` behind a new :class:`Guard` (its token)."""
    import viser

    guard = Guard()
    server = start_guarded(guard, lambda: viser.ViserServer(host=host, port=port, verbose=verbose))
    return server, guard


def start_guarded(guard: Guard, make: Callable[[], T]) -> T:
    """``make()`` (which builds a ``viser.ViserServer``) with ``guard`` in front of every
    request its websockets server receives."""
    import websockets.asyncio.server as ws_server

    original = ws_server.serve
    calls: list[bool] = []

    def serve(handler: Any, *args: Any, process_request: Any = None, **kwargs: Any) -> Any:
        calls.append(True)

        def checked(connection: Any, request: Any) -> Any:
            return guard.process_request(connection, request, process_request)

        return original(handler, *args, process_request=checked, **kwargs)

    with _PATCH_LOCK:
        ws_server.serve = serve  # type: ignore[assignment,misc]
        try:
            server = make()
        finally:
            ws_server.serve = original  # type: ignore[misc]
    if not calls:
        stop = getattr(server, "stop", None)
        if stop is not None:
            stop()
        raise RuntimeError(
            "viser did not start its server through websockets.asyncio.server.serve, so the "
            "app's token and Origin checks could not be put in front of it; refusing to run "
            "unprotected (a viser version agvsim does not know?)"
        )
    return server
