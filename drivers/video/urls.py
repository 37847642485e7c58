"""A video URL's parts: where RTP comes from (``udp://``, ``rtp://``), whose datagrams are
taken (``?source=HOST[:PORT]``), and what FFmpeg opens instead."""


import logging
import os
from urllib.parse import parse_qs, urlsplit

from drivers.video.rtp import DEFAULT_HOST

log = logging.getLogger(__name__)

def rtp_address(url: str) -> tuple[str, int] | None:
    """(host, port) of an RTP URL (``udp://`` or ``rtp://``), None for other URLs. No host (or
    ``@`` alone, once "every interface" in FFmpeg's spelling) is 127.0.0.1: listening on other
    interfaces, or sending to another machine, is asked for by name."""
    parts = urlsplit(url)
    if parts.scheme not in ("udp", "rtp") or parts.port is None:
        return None
    host = (parts.hostname or "").lstrip("@")
    return host or DEFAULT_HOST, parts.port


#: what FFmpeg is asked to open besides RTP (and files and devices, given as paths)
FFMPEG_SCHEMES = ("rtsp", "rtsps", "rtmp", "rtmps", "http", "https", "srt", "tcp", "file")


def check_video_url(url: str) -> None:
    """Refuse a video URL that cannot work, before anything opens it (:class:`ValueError`,
    saying what is accepted): RTP needs a port; other streams need a scheme FFmpeg reads;
    anything else must be an existing file or device."""
    parts = urlsplit(url)
    if parts.scheme in ("udp", "rtp"):
        try:
            port = parts.port
        except ValueError:
            port = None
        if port is None:
            raise ValueError(f"{url!r}: RTP video needs a port, e.g. udp://127.0.0.1:5600")
        source = url_source(url)
        if source is not None:
            parse_source(source)
        return
    if parts.scheme in FFMPEG_SCHEMES:
        return
    if "://" in url or not os.path.exists(url):
        raise ValueError(f"{url!r}: expected udp://HOST:PORT (RTP H.264), "
                         f"{', '.join(s + '://' for s in FFMPEG_SCHEMES[:5])}..., "
                         "or an existing file or device (/dev/video0)")


def url_source(url: str) -> str | None:
    """The ``source`` option of an RTP URL's query (None without one)."""
    options = parse_qs(urlsplit(url).query, keep_blank_values=True)
    unknown = sorted(set(options) - {"source"})
    if unknown:
        log.warning("video %s: ignoring unknown URL option(s) %s (only 'source' is known)",
                    url, ", ".join(unknown))
    values = options.get("source")
    return values[-1] if values else None


def parse_source(text: str) -> tuple[str, int | None]:
    """``HOST`` or ``HOST:PORT`` (IPv4 address or name) as (host, port or None)."""
    host, colon, port = text.strip().partition(":")
    if not host or (colon and not (port.isdigit() and 0 < int(port) < 65536)):
        raise ValueError(f"video source {text!r}: expected HOST or HOST:PORT")
    return host, int(port) if port else None


def address_text(address: tuple[str, int | None]) -> str:
    return address[0] if address[1] is None else f"{address[0]}:{address[1]}"
