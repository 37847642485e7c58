"""The console's sign-in and TLS (issue 31, item 7): off loopback the token is typed into a
sign-in page and kept as a cookie scoped to the port, HttpOnly, SameSite=Strict, and Secure
over HTTPS; ``--api-tls-cert``/``--api-tls-key`` serve the API and the console over TLS, and
a wrong pair is refused before anything starts, naming the option."""

from __future__ import annotations

import asyncio
import http.client
import json
import ssl
from types import SimpleNamespace

import pytest

from autopilot.api import ApiSetupError
from autopilot.api_server import ApiServer, check_tls
from autopilot.mission import load_mission

trustme = pytest.importorskip("trustme")
TOKEN = "a-token-of-enough-length-0123"


def _runtime():
    config = load_mission("standby").config
    return SimpleNamespace(api_status=lambda: {"status_code": 3}, goals=None, config=config)


def _serve(tls, script):
    async def main():
        desk = _runtime()  # (the console's routes: their pages and their sign-in only)
        server = ApiServer(desk, "127.0.0.1", 0, TOKEN, console=desk, tls=tls)
        task = asyncio.ensure_future(server.run())
        await server.started.wait()
        try:
            return await asyncio.to_thread(script, server.bound_port, server.scheme)
        finally:
            await server.stop(graceful=False)
            task.cancel()

    return asyncio.run(main())


def _request(conn, method, path, body=None, headers=None):
    conn.request(method, path, body=body, headers={"Host": "127.0.0.1", **(headers or {})})
    resp = conn.getresponse()
    return resp.status, {k.lower(): v for k, v in resp.getheaders()}, resp.read()


def _sign_in(conn_factory):
    out = {}
    status, headers, page = _request(conn_factory(), "GET", "/")
    out["page"] = (status, page)
    out["wrong"] = _request(conn_factory(), "POST", "/api/login",
                            json.dumps({"token": "wrong"}), {"Content-Type": "application/json"})
    status, headers, _ = _request(conn_factory(), "POST", "/api/login",
                                  json.dumps({"token": TOKEN}),
                                  {"Content-Type": "application/json"})
    out["login"] = (status, headers.get("set-cookie", ""))
    cookie = out["login"][1].split(";")[0]
    out["with_cookie"] = _request(conn_factory(), "GET", "/api/status",
                                  headers={"Cookie": cookie})[0]
    out["no_cookie"] = _request(conn_factory(), "GET", "/api/status")[0]
    out["foreign"] = _request(conn_factory(), "POST", "/api/login",
                              json.dumps({"token": TOKEN}),
                              {"Content-Type": "application/json",
                               "Origin": "http://evil.example"})[0]
    return out


def test_the_console_signs_in_with_a_typed_token_kept_as_a_scoped_cookie():
    out = _serve(None, lambda port, scheme: _sign_in(
        lambda: http.client.HTTPConnection("127.0.0.1", port, timeout=10)))
    status, page = out["page"]
    assert status == 401
    assert b"Sign in" in page
    assert TOKEN.encode() not in page
    assert out["wrong"][0] == 401
    status, cookie = out["login"]
    assert status == 204
    assert cookie.startswith("autopilot_token_")  # one per port
    assert "HttpOnly" in cookie
    assert "SameSite=strict" in cookie or "samesite=strict" in cookie.lower()
    assert "secure" not in cookie.lower()  # plain HTTP (on loopback): said in the docs
    assert out["with_cookie"] == 200
    assert out["no_cookie"] == 401
    assert out["foreign"] == 403  # another site's page cannot sign in for you


def test_tls_serves_the_api_and_the_console_with_a_secure_cookie(tmp_path):
    ca = trustme.CA()
    cert = ca.issue_cert("127.0.0.1", "localhost")
    cert_file, key_file = tmp_path / "cert.pem", tmp_path / "key.pem"
    cert.cert_chain_pems[0].write_to_path(cert_file)
    cert.private_key_pem.write_to_path(key_file)
    context = ssl.create_default_context()
    ca.configure_trust(context)

    def script(port, scheme):
        out = {"scheme": scheme}
        out.update(_sign_in(lambda: http.client.HTTPSConnection("127.0.0.1", port, timeout=10,
                                                               context=context)))
        out["bearer"] = _request(http.client.HTTPSConnection(
            "127.0.0.1", port, timeout=10, context=context), "GET", "/api/status",
            headers={"Authorization": f"Bearer {TOKEN}"})[0]
        try:  # plain HTTP to the TLS port: no answer
            _request(http.client.HTTPConnection("127.0.0.1", port, timeout=5), "GET",
                     "/api/status")
            out["plain"] = "answered"
        except (http.client.HTTPException, OSError):
            out["plain"] = "refused"
        return out

    out = _serve((str(cert_file), str(key_file)), script)
    assert out["scheme"] == "https"
    assert out["bearer"] == 200
    assert out["login"][0] == 204
    assert "secure" in out["login"][1].lower()
    assert out["with_cookie"] == 200
    assert out["plain"] == "refused"


def test_a_wrong_certificate_or_key_is_refused_naming_the_option(tmp_path):
    with pytest.raises(ApiSetupError, match=r"--api-tls-cert .*no such file"):
        check_tls(str(tmp_path / "missing.pem"), str(tmp_path / "key.pem"))
    junk = tmp_path / "junk.pem"
    junk.write_text("not a certificate")
    with pytest.raises(ApiSetupError, match="not a PEM certificate"):
        check_tls(str(junk), str(junk))
