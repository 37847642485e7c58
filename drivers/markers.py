"""Fiducial marker dictionaries, in one place: a dictionary is named either as OpenCV names it
(``DICT_ARUCO_ORIGINAL``, ``DICT_4X4_50``, ``DICT_APRILTAG_36h11``) or, for AprilTags, by its
family (``tag36h11``). The simulator prints markers from these dictionaries; the detectors,
the landing pad's layouts and the calibration boards read them."""

from __future__ import annotations

import cv2

#: AprilTag families and OpenCV's names of the same dictionaries
APRILTAG_FAMILIES = {"tag16h5": "DICT_APRILTAG_16h5", "tag25h9": "DICT_APRILTAG_25h9",
                     "tag36h11": "DICT_APRILTAG_36h11"}


def aruco_dictionary_name(name: str) -> str:
    """OpenCV's name of a dictionary given either way (``DICT_4X4_50``, ``tag36h11``); a
    ValueError listing the known names for any other."""
    name = APRILTAG_FAMILIES.get(name, name)
    if not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
        known = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_"))
        raise ValueError(f"unknown marker dictionary {name!r}; expected one of "
                         f"{', '.join(known)} or {', '.join(APRILTAG_FAMILIES)}")
    return name


def aruco_dictionary(name: str) -> cv2.aruco.Dictionary:
    """OpenCV's dictionary of that name (either way: :func:`aruco_dictionary_name`)."""
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, aruco_dictionary_name(name)))


def apriltag_family_name(name: str) -> str:
    """The AprilTag family of a dictionary given either way (``tag36h11``,
    ``DICT_APRILTAG_36h11``); a ValueError for a dictionary that is not an AprilTag family."""
    for family, dict_name in APRILTAG_FAMILIES.items():
        if name.lower() in (family, dict_name.lower()):
            return family
    raise ValueError(f"the apriltag back end reads the families {', '.join(APRILTAG_FAMILIES)} "
                     f"(or their DICT_APRILTAG_* names), not {name!r}")
