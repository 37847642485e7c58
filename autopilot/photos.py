"""Photos as survey and inspection tools expect them: JPEG files geotagged in EXIF.

A photo's position goes into the EXIF GPS block (latitude, longitude, altitude above mean sea
level, and the camera's heading), its time into DateTimeOriginal, so that photogrammetry
tools and photo viewers place it without a side file; :class:`PhotoIndex` also keeps one JSON
line per photo with what EXIF cannot hold (local position, attitude, height above home).
"""

from __future__ import annotations

import datetime as dt
import json
import math
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np
from PIL import ExifTags, Image, TiffImagePlugin


def _rational(value: float, precision: int = 10_000) -> TiffImagePlugin.IFDRational:
    frac = Fraction(value).limit_denominator(precision)
    return TiffImagePlugin.IFDRational(frac.numerator, frac.denominator)


def _dms(degrees: float) -> tuple[TiffImagePlugin.IFDRational, ...]:
    degrees = abs(degrees)
    d = int(degrees)
    minutes = (degrees - d) * 60.0
    m = int(minutes)
    s = (minutes - m) * 60.0
    return (_rational(d, 1), _rational(m, 1), _rational(round(s, 4), 10_000))


def exif_gps_block(lat_deg: float, lon_deg: float, alt_amsl_m: float,
                   heading_deg: float | None = None) -> dict[int, object]:
    """The EXIF GPS IFD for a position (WGS-84) and, if given, the camera's heading."""
    gps: dict[int, object] = {
        ExifTags.GPS.GPSVersionID: b"\x02\x03\x00\x00",
        ExifTags.GPS.GPSLatitudeRef: "N" if lat_deg >= 0 else "S",
        ExifTags.GPS.GPSLatitude: _dms(lat_deg),
        ExifTags.GPS.GPSLongitudeRef: "E" if lon_deg >= 0 else "W",
        ExifTags.GPS.GPSLongitude: _dms(lon_deg),
        ExifTags.GPS.GPSAltitudeRef: b"\x00" if alt_amsl_m >= 0 else b"\x01",
        ExifTags.GPS.GPSAltitude: _rational(abs(alt_amsl_m), 1000),
        ExifTags.GPS.GPSMapDatum: "WGS-84",
    }
    if heading_deg is not None and math.isfinite(heading_deg):
        gps[ExifTags.GPS.GPSImgDirectionRef] = "T"
        gps[ExifTags.GPS.GPSImgDirection] = _rational(heading_deg % 360.0, 100)
    return gps


@dataclass(frozen=True, slots=True)
class CameraExif:
    """What a photo's EXIF says of the camera that took it."""

    make: str = "autopilot"
    model: str = "simulated down camera"
    focal_length_mm: float | None = None
    focal_length_35mm: int | None = None  # 35 mm equivalent (36 mm wide frame)


@dataclass(frozen=True, slots=True)
class CameraPose:
    """The camera's attitude when it took a photo, as drone photos carry it in XMP (degrees:
    yaw clockwise from north, pitch up from level (−90: straight down), roll right)."""

    yaw_deg: float
    pitch_deg: float
    roll_deg: float
    relative_altitude_m: float | None = None  # above home


def xmp_packet(pose: CameraPose) -> bytes:
    """An XMP packet with the camera's attitude in the properties photogrammetry tools read
    (DJI's ``drone-dji`` namespace, which OpenDroneMap and OpenSfM understand, and the
    ``Camera`` namespace of multispectral cameras)."""
    rel = "" if pose.relative_altitude_m is None else \
        f' drone-dji:RelativeAltitude="{pose.relative_altitude_m:+.3f}"'
    return (
        '<?xpacket begin="\ufeff" id="W5M0MpCehiHzreSzNTczkc9d"?>'
        '<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF '
        'xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">'
        '<rdf:Description rdf:about="" xmlns:drone-dji="http://www.dji.com/drone-dji/1.0/" '
        'xmlns:Camera="http://pix4d.com/camera/1.0/"'
        f' drone-dji:GimbalYawDegree="{pose.yaw_deg:+.2f}"'
        f' drone-dji:GimbalPitchDegree="{pose.pitch_deg:+.2f}"'
        f' drone-dji:GimbalRollDegree="{pose.roll_deg:+.2f}"'
        f' drone-dji:FlightYawDegree="{pose.yaw_deg:+.2f}"'
        f'{rel}'
        f' Camera:Yaw="{pose.yaw_deg:.2f}" Camera:Pitch="{pose.pitch_deg + 90.0:.2f}"'
        f' Camera:Roll="{pose.roll_deg:.2f}"/>'
        '</rdf:RDF></x:xmpmeta><?xpacket end="w"?>').encode()


def write_geotagged_jpeg(path: Path, image_bgr: np.ndarray, *, lat_deg: float | None,
                         lon_deg: float | None, alt_amsl_m: float | None,
                         taken_utc: dt.datetime, heading_deg: float | None = None,
                         quality: int = 95, camera: CameraExif = CameraExif(),
                         pose: CameraPose | None = None) -> None:
    """Write ``image_bgr`` as a JPEG with its position (if known: a vehicle that has not said
    where its origin is gives none), time and camera in EXIF, and its attitude in XMP."""
    image = Image.fromarray(cv2.cvtColor(image_bgr, cv2.COLOR_BGR2RGB))
    exif = Image.Exif()
    exif[ExifTags.Base.Make] = camera.make
    exif[ExifTags.Base.Model] = camera.model
    exif[ExifTags.Base.DateTime] = taken_utc.strftime("%Y:%m:%d %H:%M:%S")
    sub = exif.get_ifd(ExifTags.IFD.Exif)
    sub[ExifTags.Base.DateTimeOriginal] = taken_utc.strftime("%Y:%m:%d %H:%M:%S")
    sub[ExifTags.Base.SubsecTimeOriginal] = f"{taken_utc.microsecond // 1000:03d}"
    sub[ExifTags.Base.ExifImageWidth] = image.width
    sub[ExifTags.Base.ExifImageHeight] = image.height
    if camera.focal_length_mm is not None:
        sub[ExifTags.Base.FocalLength] = _rational(camera.focal_length_mm, 1000)
    if camera.focal_length_35mm is not None:
        sub[ExifTags.Base.FocalLengthIn35mmFilm] = int(camera.focal_length_35mm)
    if lat_deg is not None and lon_deg is not None and alt_amsl_m is not None:
        gps = exif.get_ifd(ExifTags.IFD.GPSInfo)
        gps.update(exif_gps_block(lat_deg, lon_deg, alt_amsl_m, heading_deg))
        gps[ExifTags.GPS.GPSDateStamp] = taken_utc.strftime("%Y:%m:%d")
        gps[ExifTags.GPS.GPSTimeStamp] = (
            _rational(taken_utc.hour, 1), _rational(taken_utc.minute, 1),
            _rational(taken_utc.second + taken_utc.microsecond / 1e6, 1000))
    extra = {"xmp": xmp_packet(pose)} if pose is not None else {}
    image.save(path, "JPEG", quality=quality, exif=exif, **extra)


def read_exif_position(path: Path) -> tuple[float, float, float]:
    """(lat °, lon °, alt AMSL m) from a geotagged JPEG (for checks and tests)."""
    with Image.open(path) as image:
        gps = image.getexif().get_ifd(ExifTags.IFD.GPSInfo)

    def degrees(dms, ref) -> float:
        value = float(dms[0]) + float(dms[1]) / 60.0 + float(dms[2]) / 3600.0
        return -value if ref in ("S", "W") else value

    lat = degrees(gps[ExifTags.GPS.GPSLatitude], gps[ExifTags.GPS.GPSLatitudeRef])
    lon = degrees(gps[ExifTags.GPS.GPSLongitude], gps[ExifTags.GPS.GPSLongitudeRef])
    alt = float(gps[ExifTags.GPS.GPSAltitude])
    if gps.get(ExifTags.GPS.GPSAltitudeRef) in (b"\x01", 1):
        alt = -alt
    return lat, lon, alt


class PhotoIndex:
    """``photos/`` of a run: the JPEGs and ``photos.jsonl`` (one line per photo)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.count = 0

    def add(self, image_bgr: np.ndarray | None, record: dict,
            taken_utc: dt.datetime) -> Path | None:
        """Write one photo (None: the camera gave no image; only the record is kept)."""
        self.folder.mkdir(parents=True, exist_ok=True)
        path = None
        if image_bgr is not None:
            path = self.folder / f"photo_{record['index']:04d}.jpg"
            write_geotagged_jpeg(path, image_bgr, lat_deg=record["lat_deg"],
                                 lon_deg=record["lon_deg"], alt_amsl_m=record["alt_amsl_m"],
                                 taken_utc=taken_utc, heading_deg=record.get("yaw_deg"))
        line = dict(record, file=path.name if path is not None else None,
                    taken_utc=taken_utc.isoformat())
        with (self.folder / "photos.jsonl").open("a") as index:
            index.write(json.dumps(line) + "\n")
        self.count += 1
        return path
