"""Images on the ground (a known image, a landing pad) and a ground with features."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import mujoco
import numpy as np

from drivers.geometry import quat_from_euler
from drivers.sim.scenario.bodies import (
    BodyTruth,
    ScenarioObject,
    WorldFrame,
    yaw_quat_enu,
)


def image_rotation_ned(yaw_rad: float) -> np.ndarray:
    """``R_ned_image`` of an image lying face up with its top towards heading ``yaw_rad``:
    x along its columns (ψ + 90°), y down its rows (ψ + 180°), z into the ground."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[-s, -c, 0.0], [c, -s, 0.0], [0.0, 0.0, 1.0]])


@dataclass
class GroundImage(ScenarioObject):
    """A printed image lying flat on the ground (a thin textured plate), its top towards
    ``yaw_deg`` (NED heading), ``size_m`` wide; the height follows the image's aspect ratio.
    ``image_bgr``: the picture (OpenCV's BGR). Its truth: the image's centre on its face, and
    the heading of its top as the attitude (a yaw-only quaternion)."""

    name: str
    image_bgr: np.ndarray
    size_m: float
    north_east_m: tuple[float, float] = (0.0, 0.0)
    yaw_deg: float = 0.0
    thickness_m: float = 0.002
    max_texture_px: int = 2048
    moves: bool = False

    def __post_init__(self) -> None:
        h, w = self.image_bgr.shape[:2]
        self.height_m = self.size_m * h / w
        scale = min(1.0, self.max_texture_px / max(h, w))
        image = self.image_bgr if scale == 1.0 else cv2.resize(
            self.image_bgr, (round(w * scale), round(h * scale)), interpolation=cv2.INTER_AREA)
        # MuJoCo maps a 2D texture onto a box's +z face with its first row at the face's +y
        # edge and its columns along +x: as printed, seen from above
        self._texture = np.ascontiguousarray(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))

    @property
    def position_ned_m(self) -> np.ndarray:
        n, e = self.north_east_m
        return np.array([n, e, -self.thickness_m])

    def build(self, spec: mujoco.MjSpec, frame: WorldFrame) -> None:
        h, w = self._texture.shape[:2]
        spec.add_texture(name=f"{self.name}/texture", type=mujoco.mjtTexture.mjTEXTURE_2D,
                         width=w, height=h, nchannel=3).data = self._texture.tobytes()
        material = spec.add_material(name=f"{self.name}/face", specular=0.0, shininess=0.0,
                                     reflectance=0.0, rgba=[1.0, 1.0, 1.0, 1.0])
        material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"{self.name}/texture"
        n, e = self.north_east_m
        centre = frame.to_enu(np.array([n, e, -self.thickness_m / 2.0]))
        # the body's +x (FLU forward) along the image's columns, its +y (left) to its top
        body = spec.worldbody.add_body(name=self.name, pos=centre,
                                       quat=yaw_quat_enu(math.radians(self.yaw_deg)
                                                          + math.pi / 2.0))
        body.add_geom(name=f"{self.name}/face", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[self.size_m / 2.0, self.height_m / 2.0, self.thickness_m / 2.0],
                      material=f"{self.name}/face", contype=0, conaffinity=0)

    def truth(self, time_s: float, data: mujoco.MjData) -> BodyTruth:
        return BodyTruth(self.position_ned_m, np.zeros(3),
                         quat_from_euler(0.0, 0.0, math.radians(self.yaw_deg)))


def gravel_texture(size_px: int = 1024, seed: int = 7) -> np.ndarray:
    """An outdoor ground as the down camera sees it from a few metres (RGB): soil and sparse
    grass tones varying over several scales, strewn with small stones — features everywhere,
    none regular (not a checkerboard). Tiles seamlessly (its noise wraps)."""
    rng = np.random.default_rng(seed)
    s = size_px

    def noise(cells: int) -> np.ndarray:  # smooth, wrapping value noise in [-1, 1]
        grid = rng.uniform(-1.0, 1.0, (cells, cells)).astype(np.float32)
        tiled = np.tile(grid, (3, 3))
        big = cv2.resize(tiled, (3 * s, 3 * s), interpolation=cv2.INTER_CUBIC)
        return big[s:2 * s, s:2 * s]

    field = 0.5 * noise(8) + 0.3 * noise(32) + 0.2 * noise(128)
    soil = np.array([0.40, 0.34, 0.25])
    grass = np.array([0.30, 0.38, 0.20])
    mix = np.clip(0.5 + field, 0.0, 1.0)[:, :, None]
    image = (soil * (1.0 - mix) + grass * mix) * (1.0 + 0.25 * noise(256)[:, :, None])
    image = np.clip(image * 255.0, 0, 255).astype(np.uint8)
    for _ in range(int(s * s / 900)):  # stones, a few pixels to a few centimetres across
        x, y = (int(v) for v in rng.integers(0, s, 2))
        r = float(np.exp(rng.uniform(np.log(1.5), np.log(9.0))))
        tone = float(rng.uniform(0.45, 0.8))
        colour = tuple(int(255 * tone * c) for c in (1.0, 0.96, rng.uniform(0.8, 0.92)))
        cv2.ellipse(image, (x, y), (max(1, int(r)), max(1, int(r * rng.uniform(0.5, 1.0)))),
                    float(rng.uniform(0, 180)), 0, 360, colour, -1, cv2.LINE_AA)
    return image


@dataclass
class FeatureGround(ScenarioObject):
    """Replaces the world's ground texture with :func:`gravel_texture`, each tile
    ``tile_m`` on a side (about a centimetre a texel): what an image matcher meets outdoors
    around its target. Adds no body."""

    name: str = "ground"
    tile_m: float = 10.0
    size_px: int = 1024
    seed: int = 7
    moves: bool = False

    def build(self, spec: mujoco.MjSpec, frame: WorldFrame) -> None:
        texture, material, plane = spec.texture("ground"), spec.material("ground"), \
            spec.geom("ground")
        if texture is None or material is None or plane is None:
            raise ValueError("the world has no textured plane named 'ground'")
        image = gravel_texture(self.size_px, self.seed)
        texture.builtin = mujoco.mjtBuiltin.mjBUILTIN_NONE
        texture.width, texture.height, texture.nchannel = self.size_px, self.size_px, 3
        texture.data = image.tobytes()
        extent = 2.0 * float(plane.size[0])
        material.texrepeat = [extent / self.tile_m, extent / self.tile_m]

    def truth(self, time_s: float, data: mujoco.MjData) -> BodyTruth:
        return BodyTruth(np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))
