"""What the goal API's clients share (``autopilot goal | status | cancel | abort``): the
address and token options and one call."""

from __future__ import annotations

import argparse
import json
import sys

from autopilot.cli.common import EXIT_LINK, EXIT_OK, EXIT_USAGE
from autopilot.config import InputError


class NoApi(Exception):
    """No goal API answered at the address (exit code 4, as for a link that cannot open)."""


def add_api_options(client: argparse.ArgumentParser) -> None:
    client.add_argument("--api", default="127.0.0.1:8080", metavar="HOST:PORT",
                        help="where the run serves its goal API (default 127.0.0.1:8080)")
    client.add_argument("--api-token-file", metavar="FILE",
                        help="bearer token (else AUTOPILOT_API_TOKEN)")


class Client:
    """Calls to a run's goal API at ``args.api`` with ``args.api_token_file``'s token."""

    def __init__(self, args: argparse.Namespace) -> None:
        from autopilot.api import ApiSetupError, parse_address
        from autopilot.api_server import read_token

        try:
            host, port = parse_address(args.api)
            self.token = read_token(args.api_token_file)
        except ApiSetupError as exc:
            raise InputError(str(exc)) from None
        self.base = f"http://{host}:{port}"

    def call(self, method: str, path: str, body=None) -> tuple[int, object]:
        import urllib.error
        import urllib.request

        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path, data=data, method=method)
        if data is not None:
            req.add_header("Content-Type", "application/json")
        if self.token:
            req.add_header("Authorization", f"Bearer {self.token}")
        try:
            with urllib.request.urlopen(req, timeout=10) as resp:
                return resp.status, json.loads(resp.read() or b"null")
        except urllib.error.HTTPError as err:
            try:
                return err.code, json.loads(err.read() or b"null")
            except ValueError:
                return err.code, {"error": err.reason}
        except (urllib.error.URLError, OSError) as exc:
            raise NoApi(f"no goal API at {self.base} ({getattr(exc, 'reason', exc)}): is "
                        "'autopilot run --api' (or --console) running there?") from None


def show(code: int, body) -> int:
    """Print an answer; 0 if it was accepted, 2 if refused (the body says why)."""
    print(json.dumps(body, indent=2))
    return EXIT_OK if code < 400 else EXIT_USAGE


def no_api(exc: NoApi) -> int:
    print(f"error: {exc}", file=sys.stderr)
    return EXIT_LINK
