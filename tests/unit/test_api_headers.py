"""The goal API's answers carry hardening headers; a loopback address written out (the API
bound to 127.0.0.2) is accepted as the request's host, a name that is not loopback is not
(issue 31, item 7)."""

from __future__ import annotations

import asyncio
import json
import urllib.error
import urllib.request
from types import SimpleNamespace

from autopilot.api_server import ApiServer


def _call(port: int, path: str, host: str | None = None) -> tuple[int, dict, object]:
    req = urllib.request.Request(f"http://127.0.0.1:{port}{path}")
    if host is not None:
        req.add_header("Host", host)
    try:
        with urllib.request.urlopen(req, timeout=10) as resp:
            status, headers, body = resp.status, resp.headers, resp.read()
    except urllib.error.HTTPError as err:
        status, headers, body = err.code, err.headers, err.read()
    headers = {k.lower(): v for k, v in headers.items()}
    if headers.get("content-type", "").startswith("application/json"):
        return status, headers, json.loads(body or b"null")
    return status, headers, body


def test_headers_hosts_and_video_rate():
    runtime = SimpleNamespace(api_status=lambda: {"status_code": 3}, goals=None)

    async def main():
        server = ApiServer(runtime, "127.0.0.1", 0, None)
        task = asyncio.ensure_future(server.run())
        await server.started.wait()
        port = server.bound_port
        try:
            return await asyncio.to_thread(lambda: [
                _call(port, "/api/status"),
                _call(port, "/api/status", host=f"127.0.0.2:{port}"),
                _call(port, "/api/status", host=f"evil.example:{port}"),
                _call(port, "/api/status", host=f"10.1.2.3:{port}"),
                _call(port, "/docs"),
                _call(port, "/docs/start.js"),
                _call(port, "/docs/static/swagger-ui-bundle.js"),
                _call(port, "/redoc"),
                _call(port, "/openapi.json"),
            ])
        finally:
            await server.stop(graceful=False)
            task.cancel()

    ok, other_loopback, rebinding, lan, docs, start, bundle, redoc, schema = asyncio.run(main())
    assert ok[0] == 200
    assert ok[1]["x-content-type-options"] == "nosniff"
    assert ok[1]["referrer-policy"] == "no-referrer"
    assert other_loopback[0] == 200
    assert rebinding[0] == 403
    assert rebinding[1]["x-content-type-options"] == "nosniff"  # refusals too
    assert lan[0] == 403
    # the OpenAPI page: from the package, nothing from elsewhere, no inline script
    assert docs[0] == 200
    assert b"https://" not in docs[2]
    assert b"http://" not in docs[2]
    policy = docs[1]["content-security-policy"]
    assert "script-src 'self';" in policy
    assert "frame-ancestors 'none'" in policy
    assert b"<script>" not in docs[2]
    assert start[0] == 200
    assert b"/openapi.json" in start[2]
    assert bundle[0] == 200
    assert len(bundle[2]) > 100_000
    assert redoc[0] == 404  # (it loads from a CDN only: not served)
    assert "Goal" in schema[2]["components"]["schemas"]
