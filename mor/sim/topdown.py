"""The simulator's top camera with ArUco tags: the sim-as-robot's stand-in for the paper's overhead camera
(Supplementary D), opt-in.

A model of its own: the first-person scene's MJCF (``build_mjcf``) plus a tag on top of the robot, on top of each
object and on the floor outside each arena corner (cv2.aruco's marker images as MuJoCo textures), and a camera
looking straight down. The walls are drawn as low curbs so that they do not hide the corner tags. It is placed
from the same ``WorldState`` as the first-person scene, which it leaves untouched: first-person frames, episodes
and random streams are the same with or without it.
"""

from __future__ import annotations

import cv2
import mujoco
import numpy as np

from mor.errors import ConfigError
from mor.sim.arena import Arena
from mor.sim.rules import WorldState
from mor.sim.scene import Scene, build_mjcf
from mor.sim.tags import DICTIONARIES, ArucoTags, TopCamera

#: Pixels per bit of a tag texture.
_CELL_PX: int = 8
_CURB_HEIGHT: float = 0.1  # metres: the walls as the top camera sees them
_TAG_LIFT: float = 0.002  # metres above the floor for the corner tags (no depth fighting with the floor)
_HIDDEN: float = -10.0  # metres: where an unused or held object's tag goes (under the opaque floor)


def aruco_dictionary(name: str) -> cv2.aruco.Dictionary:
    """OpenCV's predefined ArUco dictionary ``name`` (one of ``mor.sim.tags.DICTIONARIES``)."""
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


def tag_image(dictionary: str, tag_id: int, cell_px: int = _CELL_PX) -> np.ndarray:
    """(S, S) uint8 marker ``tag_id`` with a one-bit black border and a one-bit white margin; S = (bits + 4) cells."""
    bits = DICTIONARIES[dictionary][0]
    marker = cv2.aruco.generateImageMarker(aruco_dictionary(dictionary), tag_id, (bits + 2) * cell_px, borderBits=1)
    return cv2.copyMakeBorder(marker, cell_px, cell_px, cell_px, cell_px, cv2.BORDER_CONSTANT, value=255)


def _add_tag(spec: mujoco.MjSpec, body: mujoco.MjsBody, name: str, image: np.ndarray, side: float,
             height: float) -> None:
    """A square plane of side ``side`` metres at ``height`` on ``body`` wearing ``image``; its x axis is the
    body's (the marker's left-to-right)."""
    rgb = np.repeat(image[:, :, None], 3, axis=2)
    texture = spec.add_texture(name=f"tag_{name}", type=mujoco.mjtTexture.mjTEXTURE_2D, width=image.shape[1],
                               height=image.shape[0], nchannel=3)
    texture.data = rgb.tobytes()
    material = spec.add_material(name=f"tag_{name}")
    material.texrepeat, material.texuniform = [1.0, 1.0], False
    material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"tag_{name}"
    body.add_geom(name=f"tag_{name}", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[side / 2, side / 2, 1.0],
                  pos=[0.0, 0.0, height], material=f"tag_{name}", contype=0, conaffinity=0)


def build_topdown_model(arena: Arena, n_objects: int, tags: ArucoTags, camera: TopCamera) -> mujoco.MjModel:
    """``build_mjcf``'s scene with the tags of ``tags`` (objects 0..n_objects-1) and the camera ``top``."""
    spec = mujoco.MjSpec.from_string(build_mjcf(arena, 64, n_objects))
    for k in range(arena.n_walls):
        wall = spec.geom(f"wall{k}")
        wall.size[1], wall.pos[2] = _CURB_HEIGHT / 2, _CURB_HEIGHT / 2
    for k, (tag_id, (x, y)) in enumerate(zip(tags.corner_ids, tags.corner_positions, strict=True)):
        corner = spec.worldbody.add_body(name=f"tag_corner{k}", pos=[x, y, 0.0])
        _add_tag(spec, corner, f"corner{k}", tag_image(tags.dictionary, tag_id), tags.corner_size_m, _TAG_LIFT)
    _add_tag(spec, spec.body("agent"), "agent", tag_image(tags.dictionary, tags.agent_id), tags.agent_size_m,
             tags.agent_height_m)
    for i in range(n_objects):
        body = spec.worldbody.add_body(name=f"tag_object{i}", mocap=True)
        _add_tag(spec, body, f"object{i}", tag_image(tags.dictionary, tags.object_ids[i]), tags.object_size_m,
                 tags.object_height_m)
    x, y, z = camera.position_m
    fovy = float(np.rad2deg(2.0 * np.arctan(camera.view_half_extent_m / z)))
    spec.worldbody.add_camera(name="top", pos=[x, y, z], quat=[1.0, 0.0, 0.0, 0.0], fovy=fovy)
    spec.visual.global_.offwidth, spec.visual.global_.offheight = camera.width, camera.height
    return spec.compile()


class TopDownScene(Scene):
    """The arena seen from the top camera, tags included: ``set_episode`` and ``set_state`` as for ``Scene``,
    ``render_top_down`` -> (height, width, 3) uint8. Create it in the process that renders; ``close`` it."""

    def __init__(self, arena: Arena, n_objects: int, tags: ArucoTags, camera: TopCamera) -> None:
        if n_objects > len(tags.object_ids):
            raise ConfigError(f"robot.tags.object_ids: {n_objects} objects need {n_objects} tag ids, got "
                              f"{tags.object_ids}; add their ids in params.yaml")
        self._setup(arena, build_topdown_model(arena, n_objects, tags, camera), n_objects, "top",
                    (camera.width, camera.height), show_agent=True)
        self._tag_mocap = np.array([self.model.body(f"tag_object{i}").mocapid[0] for i in range(n_objects)], int)

    def set_state(self, state: WorldState) -> None:
        """Place the robot, the objects and their tags; the held object's tag leaves the scene with it."""
        self._mocap_pos[self._tag_mocap, :2] = state.floor_positions
        self._mocap_pos[self._tag_mocap, 2] = np.where(state.on_floor(), 0.0, _HIDDEN)
        super().set_state(state)

    def render_top_down(self) -> np.ndarray:
        """The top camera's image, (height, width, 3) uint8 RGB, a new array."""
        self.draw()
        return self.read_pixels()


__all__ = ["TopDownScene", "aruco_dictionary", "build_topdown_model", "tag_image"]
