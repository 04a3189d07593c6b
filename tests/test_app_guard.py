"""Only the browser given the start-up URL's token drives the app: a page from another origin
(cross-site websocket hijacking), a client without the token, a DNS-rebinding host are all
refused in the handshake, against a real server and a real websocket client."""

from __future__ import annotations

import base64
import http.client
import urllib.error
import urllib.request

import pytest
import viser
import websockets.exceptions
from websockets.sync.client import connect

from agvsim.app.guard import Guard, app_url, start_guarded
from agvsim.net import free_port

ROOM = """\
name: room
world: {picture: "#######\\n#.....#\\n#.....#\\n#.....#\\n#######"}
robots:
  - {name: agv, model: differential, pose: {x_m: 0.0, y_m: 0.0}}
"""

PROTOCOL = f"viser-v{viser.__version__}"


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    from agvsim.app.server import App, open_session

    path = tmp_path_factory.mktemp("guard") / "room.yaml"
    path.write_text(ROOM)
    a = App(open_session(path), port=free_port())
    yield a
    a.stop()


def _ws(app, origin: str | None, cookie: str | None = None, path: str = "/"):
    headers = {}
    if cookie is not None:
        headers["Cookie"] = f"agvsim_token_{app.port}={cookie}"
    return connect(
        f"ws://127.0.0.1:{app.port}{path}",
        origin=origin,  # type: ignore[arg-type]
        additional_headers=headers,
        subprotocols=[PROTOCOL],  # type: ignore[list-item]
        open_timeout=20,
    )


def _refused(app, **kw) -> int:
    before = app.guard.refused
    with pytest.raises(websockets.exceptions.InvalidStatus) as info:
        _ws(app, **kw).close()
    assert app.guard.refused == before + 1  # turned away in the handshake: viser never saw it
    return info.value.response.status_code


def test_the_apps_own_page_with_the_token_cookie_gets_in(app):
    own = f"http://127.0.0.1:{app.port}"
    before = app.guard.refused
    with _ws(app, origin=own, cookie=app.guard.token) as ws:
        assert ws.subprotocol == PROTOCOL
        assert ws.recv(timeout=20)  # the scene and the panel come
    assert app.guard.refused == before


def test_a_page_from_another_origin_is_refused_even_with_the_cookie(app):
    for origin in ("http://evil.example", f"http://localhost:{app.port}", "null"):
        assert _refused(app, origin=origin, cookie=app.guard.token) == 403


def test_the_apps_origin_without_the_token_is_refused(app):
    own = f"http://127.0.0.1:{app.port}"
    assert _refused(app, origin=own) == 403
    assert _refused(app, origin=own, cookie="not-the-token") == 403
    assert _refused(app, origin=own, cookie=app.guard.token[:-1]) == 403


def _raw_handshake(port: int, headers: dict[str, str]) -> int:
    """The status of a websocket handshake sent with exactly ``headers`` (Host included)."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=20)
    conn.putrequest("GET", "/", skip_host=True, skip_accept_encoding=True)
    for k, v in {
        "Upgrade": "websocket",
        "Connection": "Upgrade",
        "Sec-WebSocket-Key": base64.b64encode(b"0123456789abcdef").decode(),
        "Sec-WebSocket-Version": "13",
        "Sec-WebSocket-Protocol": PROTOCOL,
        **headers,
    }.items():
        conn.putheader(k, v)
    conn.endheaders()
    status = conn.getresponse().status
    conn.close()
    return status


def test_dns_rebinding_is_refused(app):
    # a site pointing evil.example at 127.0.0.1: Origin and Host agree, but it has no token
    host = f"evil.example:{app.port}"
    before = app.guard.refused
    assert _raw_handshake(app.port, {"Host": host, "Origin": f"http://{host}"}) == 403
    assert app.guard.refused == before + 1
    # the same handshake from the app's own page, with the cookie, is switched to a websocket
    own = f"127.0.0.1:{app.port}"
    cookie = f"agvsim_token_{app.port}={app.guard.token}"
    ok = {"Host": own, "Origin": f"http://{own}", "Cookie": cookie}
    assert _raw_handshake(app.port, ok) == 101


def test_a_script_may_give_the_token_in_the_url(app):
    with _ws(app, origin=None, path=f"/?token={app.guard.token}") as ws:
        assert ws.recv(timeout=20)
    assert _refused(app, origin=None) == 403


def test_the_page_needs_the_token_and_sets_a_strict_cookie(app):
    base = f"http://127.0.0.1:{app.port}/"
    with pytest.raises(urllib.error.HTTPError) as refused:
        urllib.request.urlopen(base, timeout=20)
    assert refused.value.code == 403 and b"token" in refused.value.read()
    assert app.url == f"{base}?token={app.guard.token}"
    with urllib.request.urlopen(app.url, timeout=20) as r:
        assert r.status == 200 and b"<html" in r.read().lower()
        cookie = r.headers["Set-Cookie"]
    assert cookie.startswith(f"agvsim_token_{app.port}={app.guard.token};")
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie
    again = urllib.request.Request(base, headers={"Cookie": cookie.split(";")[0]})
    with urllib.request.urlopen(again, timeout=20) as r:
        assert r.status == 200 and "Set-Cookie" not in r.headers


@pytest.mark.parametrize(
    ("origin", "host", "same"),
    [
        ("http://127.0.0.1:8080", "127.0.0.1:8080", True),
        ("http://LOCALHOST:8080", "localhost:8080", True),
        ("https://127.0.0.1:8080", "127.0.0.1:8080", True),
        ("http://127.0.0.1:8081", "127.0.0.1:8080", False),
        ("http://127.0.0.1", "127.0.0.1:8080", False),
        ("file://", "127.0.0.1:8080", False),
        ("null", "127.0.0.1:8080", False),
        ("http://127.0.0.1:8080", None, False),
        ("ws://127.0.0.1:8080", "127.0.0.1:8080", False),
    ],
)
def test_same_origin(origin, host, same):
    assert Guard.same_origin(origin, host) is same


def test_each_launch_has_its_own_token():
    tokens = {Guard().token for _ in range(50)}
    assert len(tokens) == 50 and all(len(t) >= 32 for t in tokens)


@pytest.mark.parametrize(
    ("host", "url"),
    [
        ("127.0.0.1", "http://127.0.0.1:8080/?token=abc"),
        ("0.0.0.0", "http://127.0.0.1:8080/?token=abc"),
        ("::1", "http://[::1]:8080/?token=abc"),
        ("myhost", "http://myhost:8080/?token=abc"),
    ],
)
def test_app_url(host, url):
    assert app_url(host, 8080, "abc") == url


def test_a_server_the_guard_cannot_front_is_not_started():
    stopped = []

    class Unprotected:
        def stop(self):
            stopped.append(True)

    with pytest.raises(RuntimeError, match="refusing to run unprotected"):
        start_guarded(Guard(), Unprotected)
    assert stopped == [True]
